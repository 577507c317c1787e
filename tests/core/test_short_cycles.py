"""Endless, out-of-step motion from short cyclic sources (paper 002, sections 4.3, 6.1 and 6.2):
looping graphs, phase shifts, drifting walks and scenes of out-of-step duplicates.

The quality bar, on a 42-frame flapping cycle of four parts in a scene of 20 duplicates for 60 s:

- distinct part-frame states: for each object and each part, the state of every output frame is
  the source frame it plays, or (the frame blended out of, the frame blended into, the weight)
  inside a blend (``flockkit.graphs.blended_frames``); the distinct states over the scene's output
  frames are at least 80% of them, for every object and part;
- in step: two neighbours (``SceneAnimation.neighbours``) play in step on a frame when, in some
  part, their source frames are at most one frame apart, counted around the cycle (frame 41 and
  frame 0 are one apart); a pair is in step when it is so on more than 5% of frames; at most 5%
  of neighbour pairs are.
"""

import functools
import warnings

import numpy as np
import pytest

import flockkit
from flockkit.errors import FlockkitWarning, ValidationError
from flockkit.graphs import blended_frames, loop_period, phase_shifts, played_frames

PERIOD = 42
DT = 1 / 30
REGION = flockkit.Polygon(vertices=[[0, 0], [30, 0], [30, 30], [0, 30]])
PLAIN_LOOP = {"loops": False, "shift_blend": 0}  # the windowed builder as it was: one cut back to frame 0


def flapping(frames: int = PERIOD, period: int = PERIOD, points: int = 12) -> flockkit.Motion:
    """A bird flapping once every `period` frames, `frames` of it: two wings beating a little
    apart, a tail wagging twice a cycle and a bobbing body (12 points each, in that order)."""
    phase = 2 * np.pi * np.arange(frames)[:, None] / period
    s = np.linspace(0.1, 1.0, points)[None, :]
    zero = 0 * phase + 0 * s
    left = np.stack([-s + zero, zero, 0.6 * s * np.sin(phase)], axis=2)
    right = np.stack([s + zero, zero, 0.6 * s * np.sin(phase + 0.3)], axis=2)
    tail = np.stack([0.2 * s * np.sin(2 * phase) + zero, -0.5 - s + zero, 0.1 * np.cos(phase) + zero], axis=2)
    body = np.stack([zero, 0.5 * s - 0.2 + zero, 0.05 * np.sin(phase + 1.0) + zero], axis=2)
    return flockkit.Motion(positions=np.concatenate([left, right, tail, body], axis=1), dt=DT)


@functools.cache
def bird(**params) -> flockkit.GraphLayers:
    motion = flapping()
    parts = flockkit.Segmentation(labels=np.repeat(np.arange(4), 12), n_parts=4)
    wind = flockkit.Features(vectors=np.tile([0.5, 0.0, 0.0], (PERIOD, 1)), dt=DT)
    return flockkit.build_layers(motion, segmentation=parts, features=wind, seed=0, **params)


@functools.cache
def flock_of_birds(**params) -> flockkit.SceneAnimation:
    scene = flockkit.Scene(templates=[bird(**params)], region=REGION, counts=[20], duration=60, seed=3,
                           headings="aligned")  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        animation = scene.synthesize()
    return animation, [w for w in caught if issubclass(w.category, FlockkitWarning)]


def distinct_share(graph, walk, n_frames: int) -> float:
    """The share of distinct part-frame states (module docstring) in the first n_frames."""
    new, old, weight = (a[:n_frames] for a in blended_frames(graph, walk))
    states = {(int(n),) if w == 1 else (int(o), int(n), float(w)) for n, o, w in zip(new, old, weight)}
    return len(states) / n_frames


def pairs_in_step(animation, period: int) -> float:
    """The share of neighbour pairs in step (module docstring), frames compared around the cycle."""
    frames, near = animation.source_frames(), animation.neighbours()
    pairs = {(min(i, j), max(i, j)) for i, own in enumerate(near) for j in own}
    apart = [np.abs(frames[i] - frames[j]) % period for i, j in sorted(pairs)]
    in_step = [(np.minimum(d, period - d) <= 1).any(axis=0).mean() > 0.05 for d in apart]
    return float(np.mean(in_step))


# -- the bar ------------------------------------------------------------------------------------


def test_a_scene_of_a_42_frame_cycle_plays_varied_and_out_of_step():
    animation, caught = flock_of_birds()
    layers = animation.templates[0]
    shares = [
        distinct_share(graph, walk, animation.n_frames)
        for object_walk in animation.walks
        for graph, walk in zip(layers.graphs, object_walk.walks)
    ]
    in_step = pairs_in_step(animation, PERIOD)
    print(f"distinct part-frame states: {min(shares):.1%} at least, {np.mean(shares):.1%} on average; "
          f"neighbour pairs in step: {in_step:.1%}; report {animation.report}")  # fmt: skip
    assert min(shares) >= 0.8
    assert in_step <= 0.05 and animation.report["pairs_in_step_after"] <= 0.05
    assert not caught, [str(w.message) for w in caught]
    # every object and part starts at its own phase, not all at frame 0
    starts = animation.source_frames()[:, :, 0]
    assert all(len(np.unique(starts[:, k])) >= 10 for k in range(4)), starts


def test_the_plain_loop_it_replaces_fails_the_bar_and_is_warned_about():
    """Without loops and phase shifts the windowed builder keeps one cut from frame 41 back to 0
    per part: every walk plays the same 41 frames over and over, every duplicate in step, and the
    scene warns naming each part."""
    layers = bird(**PLAIN_LOOP)
    assert [[(t.start, t.end) for t in g.transitions] for g in layers.graphs] == [[(41, 0)]] * 4
    animation, caught = flock_of_birds(**PLAIN_LOOP)
    graph, walk = layers.graphs[0], animation.walks[0].walks[0]
    assert distinct_share(graph, walk, animation.n_frames) < 0.05
    assert pairs_in_step(animation, PERIOD) == 1.0
    parts = sorted(int(str(w.message).split(" part ")[1].split()[0]) for w in caught)
    assert parts == [0, 1, 2, 3]
    assert all("template 0" in str(w.message) and "1 transition" in str(w.message) for w in caught)


# -- looping sources and graphs -------------------------------------------------------------------


def test_loop_period_tells_a_cycle_from_a_recording_that_does_not_loop():
    assert loop_period(flapping()) == PERIOD  # frame 0 follows frame 41
    assert loop_period(flapping(frames=PERIOD + 1)) == PERIOD  # frame 42 repeats frame 0
    assert loop_period(flapping(frames=30)) is None  # stops mid-beat
    assert loop_period(flapping(frames=60)) is None  # a beat and a half
    still = flockkit.Motion(positions=np.zeros((10, 3, 3)), dt=DT)
    assert loop_period(still) is None
    with pytest.raises(ValidationError, match="Motion"):
        loop_period(np.zeros((10, 3, 3)))


def test_the_windowed_builder_loops_a_cycle_and_adds_phase_shifts():
    graph = bird().graphs[0]
    assert graph.loops and graph.period == PERIOD
    assert list(graph.nodes) == list(range(PERIOD))  # a walk may start at any phase
    last = graph.clips[-1]
    assert (last.source, last.target, last.start, last.stop) == (PERIOD - 1, 0, PERIOD - 1, PERIOD)
    shifts = graph.shifts
    assert sorted(set(shifts.tolist())) == [-2, -1, 1, 2] and np.all(shifts != 0)
    blend = round(0.6 / DT)
    assert all(t.blend == blend for t in graph.transitions)
    assert graph.stats()["phase_shifts"] == 4 * PERIOD and graph.stats()["period"] == PERIOD
    # a source that does not loop keeps its clips in the recording
    plain = flockkit.build_graph(flapping(frames=60), builder="windowed")
    assert not plain.loops and len(plain.clips) == len(plain.nodes) - 1


def test_a_looping_graph_finds_transitions_within_the_cycle_and_across_its_seam():
    """Two beats a cycle, the second a little weaker: the graph jumps between the beats anywhere
    in the cycle, the windows and blends running on across the seam, where the plain builder cuts
    from the last frame (no frame after it to blend) and finds fewer."""
    beat = 2 * np.pi * np.arange(PERIOD)[:, None] / (PERIOD / 2)
    weaker = 0.6 * (1 + 0.03 * np.cos(2 * np.pi * np.arange(PERIOD)[:, None] / PERIOD))
    tips = np.linspace(0.1, 1.0, 6)[None, :]
    wing = np.stack(np.broadcast_arrays(tips, 0.0 * tips, weaker * tips * np.sin(beat)), axis=2)
    motion = flockkit.Motion(positions=wing, dt=DT)
    graph = flockkit.build_graph(motion, builder="windowed")
    within = [(t.start, t.end, t.blend) for t, shift in zip(graph.transitions, graph.shifts) if not shift]
    assert graph.period == PERIOD and len(within) >= 4
    assert all(min(abs(a - b), PERIOD - abs(a - b)) == PERIOD // 2 for a, b, _ in within)  # beat to beat
    assert (PERIOD - 1, PERIOD // 2 - 1, 9) in within  # from the last frame, blended over 0.3 s
    plain = flockkit.build_graph(motion, builder="windowed", **PLAIN_LOOP)
    assert (PERIOD - 1, PERIOD // 2 - 1, 0) in [(t.start, t.end, t.blend) for t in plain.transitions]  # a cut
    assert len(plain.transitions) < len(within)


def test_synthesis_runs_on_across_the_loop_without_a_jump():
    graph = bird().graphs[0]
    clips = [("clip", k % PERIOD) for k in range(30, 30 + 2 * PERIOD)]
    walk = flockkit.Walk(start=30, edges=clips)
    frames, _ = played_frames(graph, walk)
    np.testing.assert_array_equal(frames, (30 + np.arange(len(frames))) % PERIOD)
    # a phase shift near the end of the cycle blends the motion it leaves on across the loop
    shift = next(i for i, t in enumerate(graph.transitions) if t.start == 38 and graph.shifts[i] == 2)
    walk = flockkit.Walk(start=30, edges=[("clip", k) for k in range(30, 38)] + [("transition", shift)]
                         + [("clip", k % PERIOD) for k in range(40, 80)])  # fmt: skip
    new, old, weight = blended_frames(graph, walk)
    blend = graph.transitions[shift].blend
    np.testing.assert_array_equal(old[8 : 8 + blend], (38 + np.arange(blend)) % PERIOD)
    np.testing.assert_array_equal(new[8 : 8 + blend], (40 + np.arange(blend)) % PERIOD)
    played = flockkit.synthesize(graph, walk).positions
    source = graph.motion.positions
    largest = np.linalg.norm(np.diff(np.concatenate([source, source[:1]]), axis=0), axis=2).max()
    # the shift plays 2 frames more over its blend: its steps grow by at most 1.5 * 2 / (blend + 1)
    assert np.linalg.norm(np.diff(played, axis=0), axis=2).max() <= largest * (1 + 3 / (blend + 1)) + 1e-12


def test_looping_graphs_and_layers_are_saved_and_loaded(tmp_path):
    import json
    import zipfile

    layers = bird()
    layers.graphs[0].save(tmp_path / "graph.npz")
    again = flockkit.MotionGraph.load(tmp_path / "graph.npz")
    assert again == layers.graphs[0] and again.period == PERIOD
    layers.save(tmp_path / "layers.npz")
    assert flockkit.GraphLayers.load(tmp_path / "layers.npz") == layers

    def version(path):
        with zipfile.ZipFile(path) as archive:
            return json.loads(np.load(archive.open("__metadata__.npy")).tobytes())["version"]

    plain = bird(**PLAIN_LOOP)
    plain.save(tmp_path / "plain.npz")
    plain.graphs[0].save(tmp_path / "plain-graph.npz")
    # files older flockkit can read stay as they were; looping ones are marked as a newer format
    assert (version(tmp_path / "plain.npz"), version(tmp_path / "plain-graph.npz")) == (1, 1)
    assert (version(tmp_path / "layers.npz"), version(tmp_path / "graph.npz")) == (2, 2)


def test_bad_looping_graphs_are_refused_by_name():
    graph = bird().graphs[0]
    motion, transitions = graph.motion, graph.transitions
    with pytest.raises(ValidationError, match="MotionGraph.period"):
        flockkit.MotionGraph(motion=motion, nodes=graph.nodes, clips=graph.clips, transitions=transitions,
                             period=PERIOD + 1)  # fmt: skip
    with pytest.raises(ValidationError, match="MotionGraph.period"):
        flockkit.MotionGraph(motion=motion, nodes=graph.nodes, clips=graph.clips, transitions=transitions, period=1)
    with pytest.raises(ValidationError, match="clips"):  # a looping graph's clips go round the loop
        flockkit.MotionGraph(motion=motion, nodes=graph.nodes, clips=graph.clips[:-1], transitions=transitions,
                             period=PERIOD)  # fmt: skip
    with pytest.raises(ValidationError, match="outside the loop"):
        identity = transitions[0].alignment
        flockkit.MotionGraph.assemble(motion, [(3, 40, identity, 4)], period=30)
    with pytest.raises(ValidationError, match="blend to hide"):
        phase_shifts(motion, [0], sizes=[3], blend=6, period=PERIOD)


# -- walks ----------------------------------------------------------------------------------------


def walk_of(strategy: str, seed: int, **params):
    layers = bird()
    graph = layers.graphs[0]
    if strategy == "annotated":
        params = {"target": [(0.0, [0.5, 0.0, 0.0])], "features": layers.features, **params}
    return graph, flockkit.walk(graph, strategy=strategy, duration=60, seed=seed, **params)


@pytest.mark.parametrize("strategy", ["random", "annotated"])
def test_walks_of_a_looping_graph_play_a_minute_that_fits(strategy):
    graph, walk = walk_of(strategy, 1)
    played = flockkit.synthesize(graph, walk)
    assert played.duration >= 60
    assert distinct_share(graph, walk, 1800) >= 0.8


def test_a_region_walk_handles_a_looping_graph():
    graph = bird().graphs[0]
    box = flockkit.Box(lower=[-5, -5, -5], upper=[5, 5, 5])
    walk = flockkit.walk(graph, strategy="region", region=box, duration=20, seed=2)
    assert flockkit.synthesize(graph, walk).duration >= 20


def test_an_annotated_walk_drifts_at_most_its_drift_and_starts_anywhere():
    starts = set()
    for seed in range(8):
        graph, walk = walk_of("annotated", seed)
        frames, _ = played_frames(graph, walk)
        straight = (graph.nodes[walk.start] + np.arange(len(frames))) % PERIOD
        offset = (frames - straight + PERIOD // 2) % PERIOD - PERIOD // 2
        assert np.abs(offset).max() <= 2 and np.ptp(offset) >= 2  # it wavers, within 2 frames
        starts.add(int(graph.nodes[walk.start]))
    assert len(starts) >= 5
    graph, still = walk_of("annotated", 0, drift=0)
    assert not any(kind == "transition" for kind, _ in still.edges)  # drift 0: the plain loop
    strategy = flockkit.get("walk", "annotated", target=[(0.0, [0.5, 0.0, 0.0])], features=bird().features)
    drifting = walk_of("annotated", 0)[1]
    assert sum(kind == "transition" for kind, _ in drifting.edges) > 50
    energy = strategy.energy(graph, drifting)
    assert energy["N_T"] == 0 and energy["C_T"] == 0  # phase shifts are no transitions in E


def test_an_annotated_walk_keeps_out_of_step_with_the_walks_it_avoids():
    graph = bird().graphs[0]
    others = np.stack([played_frames(graph, walk_of("annotated", seed)[1])[0][:1800] for seed in range(6)])
    graph, walk = walk_of("annotated", 99, avoid=others)
    frames = played_frames(graph, walk)[0][:1800]
    apart = np.abs(frames[None] - others) % PERIOD
    in_step = (np.minimum(apart, PERIOD - apart) <= 1).mean(axis=1)
    assert in_step.max() <= 0.05, in_step
