import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import ValidationError


@pytest.fixture(scope="module")
def recording():
    return flockkit.simulate(n_agents=10, steps=300, seed=4)


@pytest.fixture(scope="module")
def graph(recording):
    return flockkit.build_graph(recording, seed=1)


def steps(motion):
    return np.linalg.norm(np.diff(motion.positions, axis=0), axis=-1)


def assert_no_jumps(synthesized, source):
    """No frame-to-frame step well beyond the largest the source ever takes, for any agent."""
    assert steps(synthesized).max() <= 2.5 * steps(source).max()


def test_random_walk_is_deterministic_and_long_enough(graph):
    first = flockkit.walk(graph, duration=60, seed=5)
    assert first == flockkit.walk(graph, duration=60, seed=5)
    assert first != flockkit.walk(graph, duration=60, seed=6)
    motion = flockkit.synthesize(graph, first)
    assert motion.duration >= 60 and motion.n_agents == 10 and motion.dt == graph.motion.dt


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_synthesis_has_no_jumps(graph, recording, seed):
    walk = flockkit.walk(graph, duration=40, seed=seed)
    assert_no_jumps(flockkit.synthesize(graph, walk), recording)


def test_transition_keeps_world_positions_and_identities(graph):
    """Across a transition the group stays where it was, each agent near its own last position."""
    index, transition = next((i, t) for i, t in enumerate(graph.transitions) if 0 < t.source and t.target < len(graph.clips))
    edges = [("clip", k) for k in range(transition.source)] + [("transition", index), ("clip", transition.target)]
    motion = flockkit.synthesize(graph, flockkit.Walk(start=0, edges=edges))
    at = transition.start - graph.nodes[0]  # output frame where the transition happens
    jump = np.linalg.norm(motion.positions[at] - motion.positions[at - 1], axis=1)
    assert jump.max() <= 2.5 * steps(graph.motion).max()


def test_unblended_transitions_would_jump(recording):
    """The blend is what removes the jump: with blend 0 the same walks jump (the test above is not vacuous)."""
    graph = flockkit.build_graph(recording, seed=1, blend_time=0.0)
    worst = max(steps(flockkit.synthesize(graph, flockkit.walk(graph, duration=40, seed=s))).max() for s in range(5))
    assert worst > 2.5 * steps(recording).max()


def test_region_walk_keeps_the_center_of_mass_inside(graph):
    for region in (flockkit.Ball(center=[3.0, -2.0], radius=8.0), flockkit.Box(lower=[-9.0, -9.0], upper=[9.0, 9.0]),
                   flockkit.Polygon(vertices=[[-10, -10], [10, -10], [10, 10], [0, 2], [-10, 10]])):
        walk = flockkit.walk(graph, strategy="region", region=region, duration=60, seed=2)
        motion = flockkit.synthesize(graph, walk)
        assert motion.duration >= 60
        assert region.contains(motion.center_of_mass()).all()


def test_impossible_region_is_an_error_not_a_loop(graph):
    with pytest.raises(ValidationError, match="region"):
        flockkit.walk(graph, strategy="region", region=flockkit.Ball(center=[0.0, 0.0], radius=0.3), duration=60, seed=0)
    with pytest.raises(ValidationError, match="3D"):
        flockkit.walk(graph, strategy="region", region=flockkit.Ball(center=[0.0, 0.0, 0.0], radius=5.0), duration=10)


def test_batch_synthesis(graph):
    walks = [flockkit.walk(graph, duration=20, seed=s) for s in range(50)]
    crowd = flockkit.synthesize_many(graph, walks)
    assert crowd.n_agents == 50 * 10 and crowd.n_frames == min(flockkit.synthesize(graph, w).n_frames for w in walks)
    np.testing.assert_array_equal(crowd.positions[:, 30:40], flockkit.synthesize(graph, walks[3]).positions[: crowd.n_frames])
    with pytest.raises(ValidationError, match="n_frames"):
        flockkit.synthesize_many(graph, walks, n_frames=10**6)


def test_bad_walks_are_refused(graph):
    other = next(i for i, t in enumerate(graph.transitions) if t.source != 0)
    with pytest.raises(ValidationError, match="does not leave node 0"):
        flockkit.synthesize(graph, flockkit.Walk(start=0, edges=[("transition", other)]))
    first = next(i for i, t in enumerate(graph.transitions) if t.source == 0)
    target = graph.transitions[first].target
    at_target = next((i for i, t in enumerate(graph.transitions) if t.source == target), None)
    if at_target is not None:
        with pytest.raises(ValidationError, match="blend"):
            flockkit.synthesize(graph, flockkit.Walk(start=0, edges=[("transition", first), ("transition", at_target)]))
    with pytest.raises(ValidationError, match="Walk.start"):
        flockkit.synthesize(graph, flockkit.Walk(start=10**6, edges=[]))
    with pytest.raises(ValidationError):
        flockkit.Walk(start=0, edges=[("hop", 1)])
    with pytest.raises(ValidationError, match="duration"):
        flockkit.walk(graph, duration=-1)


def test_build_graph_records_provenance(graph):
    assert graph.provenance["metric"] == "icp-hungarian" and graph.provenance["builder"] == "kovar"
    assert graph.provenance["seed"] == 1 and graph.provenance["flockkit"] == flockkit.__version__


def test_sticklebacks_sixty_second_walk(shared_data):
    table = np.loadtxt(shared_data / "sticklebacks-5" / "ground_truth.csv", delimiter=",")
    fish = flockkit.Motion(positions=table[:, 1:].reshape(-1, 5, 2), dt=1 / 15)
    graph = flockkit.build_graph(fish, seed=0)
    assert graph.stats()["transitions"] >= 3
    motion = flockkit.synthesize(graph, flockkit.walk(graph, duration=60, seed=0))
    assert motion.duration >= 60
    assert_no_jumps(motion, fish)
