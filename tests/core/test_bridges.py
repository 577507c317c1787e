"""Solver-made bridges (flockkit.graphs.bridge): a small recording, so that each solve is quick."""

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

import flockkit
from flockkit.errors import ValidationError


@pytest.fixture(scope="module")
def small():
    """6 boids for 30 s, a graph with 1 s blends, and that graph bridged along its plan."""
    recording = flockkit.simulate(n_agents=6, steps=300, seed=3)
    graph = flockkit.build_graph(recording, seed=3, blend_time=1.0, min_transitions=10)
    plan = flockkit.graphs.bridge_plan(graph, seconds=3.0, degrees=20.0)
    bridged = flockkit.graphs.bridge(graph, plan, behavior="boids", seconds=3.0, refine=10, seed=1)
    return recording, graph, plan, bridged


def largest_step(positions):
    return np.linalg.norm(np.diff(positions, axis=0), axis=-1).max()


def test_the_plan_follows_the_recording_turning_both_ways(small):
    recording, graph, plan, _ = small
    length = 30
    turned = [degrees for a, b, degrees in plan if b == a + length]
    assert turned and set(turned) <= {20.0, -20.0} and len(set(turned)) == 2
    assert all(0 <= a <= recording.n_frames - 2 and 0 <= b <= recording.n_frames - 2 for a, b, _ in plan)


def test_a_bridge_meets_its_ends_exactly(small):
    """Each visit is a node whose two frames are the recorded frames moved rigidly (point
    constraints: to 1e-9), joined to them by a transition each way."""
    recording, _, _, bridged = small
    first = bridged.params["bridge_frames"]
    assert first == recording.n_frames
    x = bridged.motion.positions
    np.testing.assert_array_equal(x[:first], recording.positions)
    portals = [t for t in bridged.transitions if t.start >= first and t.end < first]
    assert portals
    for t in portals:
        a = t.alignment
        for k in (0, 1):
            copy = x[t.end + k][a.assignment] @ a.rotation.T + a.translation
            assert np.abs(x[t.start + k] - copy).max() <= 1e-9
        assert a.distance == 0.0


def test_the_bridged_graph_is_valid_strongly_connected_and_saved_whole(small, tmp_path):
    _, graph, _, bridged = small
    made = [s for s in bridged.params["bridges"]["stretches"] if s["made"]]
    assert made and len(bridged.nodes) > len(graph.nodes)
    k = len(bridged.nodes)
    rows = [c.source for c in bridged.clips] + [t.source for t in bridged.transitions]
    cols = [c.target for c in bridged.clips] + [t.target for t in bridged.transitions]
    adjacency = np.zeros((k, k))
    adjacency[rows, cols] = 1
    assert connected_components(adjacency, directed=True, connection="strong")[0] == 1
    bridged.save(tmp_path / "bridged.npz")
    assert flockkit.MotionGraph.load(tmp_path / "bridged.npz") == bridged


def test_every_stretch_is_scored_and_the_made_ones_pass(small):
    _, _, _, bridged = small
    report = bridged.params["bridges"]
    for stretch in report["stretches"]:
        assert np.isfinite(stretch["log_plausibility"])
        if stretch["made"]:
            assert stretch["log_plausibility"] >= report["min_plausibility"]
            assert stretch["step_ratio"] <= flockkit.graphs.bridges.STEP_LIMIT
        else:
            assert stretch["why"]


def test_walks_through_bridges_keep_the_step_bar(small):
    """Random walks that take the bridges: where they play a bridge's frames (or blend into or out
    of them), no step beyond 1.5x the recording's largest."""
    recording, _, _, bridged = small
    first = bridged.params["bridge_frames"]
    took = 0
    for seed in range(6):
        walk = flockkit.walk(bridged, duration=60, seed=seed, turns=True)
        into, out_of, _ = flockkit.graphs.blended_frames(bridged, walk)
        bridging = (into >= first) | (out_of >= first)
        steps = np.linalg.norm(np.diff(flockkit.synthesize(bridged, walk).positions, axis=0), axis=-1).max(axis=1)
        through = steps[bridging[1:] | bridging[:-1]]
        took += len(through) > 0
        assert np.all(through <= 1.5 * largest_step(recording.positions))
    assert took


def test_a_threshold_above_every_score_refuses_all_and_keeps_the_graph(small):
    _, graph, plan, _ = small
    kept = flockkit.graphs.bridge(graph, plan[:1], behavior="boids", seconds=3.0, refine=2, min_plausibility=1e9)
    assert kept.nodes.tolist() == graph.nodes.tolist() and kept.motion == graph.motion
    assert not any(s["made"] for s in kept.params["bridges"]["stretches"])


def test_bad_bridges_are_refused_naming_what(small):
    recording, graph, _, _ = small
    with pytest.raises(ValidationError, match="seconds must cover"):
        flockkit.graphs.bridge(graph, [(0, 50)], behavior="boids", seconds=0.3)
    with pytest.raises(ValidationError, match="no frame after it"):
        flockkit.graphs.bridge(graph, [(0, recording.n_frames - 1)], behavior="boids", seconds=3.0)
    with pytest.raises(ValidationError, match="degrees"):
        flockkit.graphs.bridge(graph, [(0, 50, 200)], behavior="boids", seconds=3.0)
    with pytest.raises(ValidationError, match="pairs is empty"):
        flockkit.graphs.bridge(graph, [], behavior="boids", seconds=3.0)
    with pytest.raises(ValidationError, match="MotionGraph"):
        flockkit.graphs.bridge(recording, [(0, 50)], behavior="boids")


def test_a_dead_end_joins_the_graph_and_walks_pass_through_it(small):
    """The recording's tail, which the plain graph trims as a dead end, is in the bridged graph
    (the chain carries on from it), and random walks play it and the chain with no step beyond the
    bar there (the graph's own transitions are another matter: 1.64x on this 6-boid graph)."""
    recording, graph, _, bridged = small
    first = bridged.params["bridge_frames"]
    dead = np.arange(graph.nodes[-1] + 1, recording.n_frames)
    assert len(dead) > graph.transitions[0].blend  # the plain graph has a dead end, more than a blend long
    kept = np.concatenate([np.arange(c.start, c.stop + 1) for c in bridged.clips])
    assert np.isin(dead, kept).all()
    passed = 0
    for seed in range(8):
        walk = flockkit.walk(bridged, duration=60, seed=seed)
        into, out_of, _ = flockkit.graphs.blended_frames(bridged, walk)
        passed += bool(np.isin(into, dead).any() and (into >= first).any())
        new = (into > graph.nodes[-1]) | (out_of > graph.nodes[-1])  # the dead end, the chain, blends into them
        steps = np.linalg.norm(np.diff(flockkit.synthesize(bridged, walk).positions, axis=0), axis=-1).max(axis=1)
        assert np.all(steps[new[1:] | new[:-1]] <= 1.5 * largest_step(recording.positions))
    assert passed
