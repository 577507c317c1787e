import networkx as nx
import numpy as np
import pytest
from scipy.spatial.distance import squareform

import flockkit
from flockkit.errors import FileFormatError, ValidationError

METRIC = flockkit.get("metric", "icp-hungarian")


@pytest.fixture(scope="module")
def recording():
    return flockkit.simulate(n_agents=6, steps=160, seed=11)


@pytest.fixture(scope="module")
def graph(recording):
    return flockkit.get("builder", "kovar").build(recording, METRIC, np.random.default_rng(0))


def fish(shared_data):
    table = np.loadtxt(shared_data / "sticklebacks-5" / "ground_truth.csv", delimiter=",")
    return flockkit.Motion(positions=table[:, 1:].reshape(-1, 5, 2), dt=1 / 15)


def matched(graph):
    """The transitions the metric found (turns left out)."""
    return [t for t in graph.transitions if not t.is_turn]


def structure(graph):
    return list(graph.nodes), graph.clips, graph.transitions


def test_pruning_gives_the_identical_graph(recording, graph):
    full = flockkit.get("builder", "kovar", prune=False).build(recording, METRIC, np.random.default_rng(0))
    assert structure(full) == structure(graph) and full.stats() == graph.stats()
    assert graph.params["evaluated"] <= full.params["evaluated"]


def test_pruning_identical_with_an_absolute_threshold(recording, graph):
    threshold = min(t.alignment.distance for t in matched(graph))
    pruned, full = (
        flockkit.get("builder", "kovar", threshold=threshold, prune=prune).build(
            recording, METRIC, np.random.default_rng(0)
        )
        for prune in (True, False)
    )
    assert structure(pruned) == structure(full)


def test_pruned_probing_upwards_gives_the_identical_graph(recording, graph, monkeypatch):
    """A first probe far too low: the pruned build doubles it until the adaptive rule is decided."""
    import flockkit_kovar.builder as kovar

    monkeypatch.setattr(kovar.Kovar, "_first_probe", lambda self, *args: (1e-6, 2))
    assert structure(flockkit.get("builder", "kovar").build(recording, METRIC, np.random.default_rng(0))) == structure(
        graph
    )


def test_pruning_gives_the_identical_graph_in_a_large_group():
    """From SAMPLED_BELOW agents the metric lists single pairs without sampling rotations."""
    import flockkit_icp.metric as icp

    recording = flockkit.simulate(n_agents=icp.SAMPLED_BELOW, steps=500, seed=6)
    pruned, full = (
        flockkit.get("builder", "kovar", prune=prune).build(recording, METRIC, np.random.default_rng(0))
        for prune in (True, False)
    )
    assert structure(pruned) == structure(full) and pruned.params["evaluated"] < full.params["evaluated"]


def test_pruned_build_probing_from_strips_is_identical(monkeypatch):
    """A recording long enough for the first probe to come from strips of rows (here a little low:
    the probe goes up from it)."""
    import flockkit_kovar.builder as kovar

    recording = flockkit.simulate(n_agents=10, steps=500, seed=3)
    steps, estimate = [], kovar.Kovar._first_probe

    def spy(self, *args):
        probe, step = estimate(self, *args)
        steps.append(step)
        return probe, step

    monkeypatch.setattr(kovar.Kovar, "_first_probe", spy)
    pruned = flockkit.get("builder", "kovar").build(recording, METRIC, np.random.default_rng(0))
    full = flockkit.get("builder", "kovar", prune=False).build(recording, METRIC, np.random.default_rng(0))
    assert steps == [1.1]  # the strips gave the estimate
    assert structure(pruned) == structure(full) and pruned.params["evaluated"] < full.params["evaluated"]


def test_adaptive_threshold_is_the_last_local_minimum_taken():
    """The adaptive rule takes the lowest local minima of the difference matrix until enough
    transitions survive the trimming of dead ends: its threshold is one of them. (With the default
    30, this short recording has too few: every minimum is taken. It is longer than the shared
    one, whose few minima, all taken, leave fewer than 4 transitions.)"""
    recording = flockkit.simulate(n_agents=6, steps=200, seed=11)
    graph = flockkit.get("builder", "kovar", min_transitions=4).build(recording, METRIC, np.random.default_rng(0))
    frames = np.arange(graph.params["candidates"]) * graph.params["stride"]
    values = squareform(METRIC.pairwise([recording.configuration(int(f)) for f in frames]))
    np.fill_diagonal(values, np.inf)
    padded = np.pad(values, 1, constant_values=np.inf)
    k = len(values)
    neighbors = [padded[1 + di : k + 1 + di, 1 + dj : k + 1 + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
    is_min = np.all([values <= n for n in neighbors], axis=0) & (np.abs(frames[:, None] - frames[None, :]) >= 10)
    minima = {(int(frames[i]), int(frames[j])): values[i, j] for i, j in zip(*np.nonzero(is_min))}
    threshold = graph.params["threshold"]
    assert threshold in minima.values()
    assert {(t.start, t.end) for t in matched(graph)} <= {ij for ij, value in minima.items() if value <= threshold}
    assert len(matched(graph)) >= 4


def test_graph_is_strongly_connected_and_consistent(recording, graph):
    stats = graph.stats()
    assert stats["transitions"] >= 2 and 0 < stats["fraction_kept"] <= 1
    network = graph.to_networkx()
    assert nx.is_strongly_connected(network) and network.number_of_edges() == stats["edges"]
    for t in matched(graph):
        assert abs(t.end - t.start) >= 10  # min_gap 1 s at dt 0.1
        a, b = recording.configuration(t.start), recording.configuration(t.end)
        assert t.alignment.residual(a, b) <= t.alignment.distance * (1 + 1e-9)  # positions, plus the velocity term
        assert t.alignment.distance <= graph.params["threshold"]


def test_transitions_are_local_minima_of_the_difference_matrix(recording, graph):
    stride = graph.params["stride"]
    last = (graph.params["candidates"] - 1) * stride  # the builder's last candidate frame
    for t in matched(graph)[:6]:
        for di in (-stride, 0, stride):
            for dj in (-stride, 0, stride):
                i, j = t.start + di, t.end + dj
                if (di or dj) and i != j and 0 <= i and 0 <= j and max(i, j) <= last:
                    neighbor = METRIC.compare(recording.configuration(i), recording.configuration(j)).distance
                    assert t.alignment.distance <= neighbor + 1e-9


def test_save_load_round_trip(graph, tmp_path):
    path = tmp_path / "graph.npz"
    graph.save(path)
    loaded = flockkit.MotionGraph.load(path)
    assert loaded == graph and loaded.stats() == graph.stats()
    with pytest.raises(FileFormatError, match="'motion'"):
        flockkit.MotionGraph.load(_motion_file(tmp_path))
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(FileFormatError, match="truncated.npz"):
        flockkit.MotionGraph.load(truncated)
    corrupt = tmp_path / "corrupt.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["transition_nodes"] = arrays["transition_nodes"] + 10_000  # nodes that do not exist
    np.savez(corrupt, **arrays)
    with pytest.raises(FileFormatError, match="invalid motion graph"):
        flockkit.MotionGraph.load(corrupt)


def test_a_graph_needs_a_transition(recording):
    with pytest.raises(ValidationError, match="at least one transition"):
        flockkit.MotionGraph(motion=recording, nodes=[0], clips=[], transitions=[])


def _motion_file(tmp_path):
    path = tmp_path / "motion.npz"
    flockkit.simulate(n_agents=2, steps=3, seed=0).save(path)
    return path


def test_paper_rule_and_absolute_threshold(recording):
    per_second = flockkit.get("builder", "kovar", per_second=0.2).build(recording, METRIC, np.random.default_rng(0))
    assert per_second.params["threshold_rule"] == "per_second"
    minima = int(np.ceil(0.2 * recording.duration))
    assert 1 <= len(matched(per_second)) <= 2 * minima  # both directions of each chosen minimum
    with pytest.raises(ValidationError, match="leaves no transition") as info:
        flockkit.get("builder", "kovar", threshold=1e-12).build(recording, METRIC, np.random.default_rng(0))
    working = float(str(info.value).split("threshold=")[1].split()[0])
    assert "smallest transition cost is" in str(info.value)
    assert (
        flockkit.get("builder", "kovar", threshold=working)
        .build(recording, METRIC, np.random.default_rng(0))
        .transitions
    )


def _failure(motion, **params):
    """(the error message, pairs computed) of a build that finds no graph."""
    computed = []

    def progress(done, total, stage):
        if stage == "difference matrix" and done == 0:
            computed.append(total)

    with pytest.raises(ValidationError) as info:
        flockkit.get("builder", "kovar", **params).build(motion, METRIC, np.random.default_rng(0), progress=progress)
    return str(info.value), sum(computed)


def test_a_failed_build_names_the_same_threshold_pruned_or_not_computing_less(recording):
    """Pruned, the threshold that works is searched upwards from the one given, computing only
    what each probe needs; the message is the one a complete matrix gives."""
    pruned, pruned_pairs = _failure(recording, threshold=1e-12)
    full, full_pairs = _failure(recording, threshold=1e-12, prune=False)
    assert pruned == full and "threshold=" in pruned
    assert pruned_pairs < full_pairs


def test_a_group_that_never_recurs_gets_no_graph_whatever_the_threshold():
    """A group that only grows: no local minimum of E under its mean squared radius."""
    base = np.array([[1.0, 0.0], [0.0, 1.2], [-0.9, 0.1], [0.2, -1.1]])
    t = np.arange(120) * 0.1
    growing = flockkit.Motion(positions=base * np.exp(0.1 * t)[:, None, None] + [0.5, 0.0] * t[:, None, None], dt=0.1)
    messages = {_failure(growing, prune=prune)[0] for prune in (True, False)}
    messages |= {_failure(growing, prune=prune, threshold=1e-9)[0] for prune in (True, False)}
    (message,) = messages
    assert "no threshold up to" in message and "no local minimum" in message


def test_parallel_build_is_identical(recording, graph):
    parallel = flockkit.get("builder", "kovar", n_jobs=2).build(recording, METRIC, np.random.default_rng(0))
    assert parallel == graph


def test_sticklebacks_default_graph_and_pruning(shared_data):
    graph = flockkit.get("builder", "kovar").build(fish(shared_data), METRIC, np.random.default_rng(0))
    assert graph.stats()["transitions"] >= 3
    assert nx.is_strongly_connected(graph.to_networkx())
    full = flockkit.get("builder", "kovar", prune=False).build(fish(shared_data), METRIC, np.random.default_rng(0))
    assert structure(full) == structure(graph)
    assert graph.params["evaluated"] < full.params["evaluated"] / 2  # the lower bound skipped most cells


@pytest.mark.parametrize(
    "params, name",
    [
        ({"candidate_interval": 0}, "candidate_interval"),
        ({"min_transitions": 0}, "min_transitions"),
        ({"threshold": -1.0}, "threshold"),
        ({"n_jobs": 0}, "n_jobs"),
        ({"prune": "yes"}, "prune"),
    ],
)
def test_bad_parameters(params, name):
    with pytest.raises(ValidationError, match=name):
        flockkit.get("builder", "kovar", **params)


def test_too_short_a_recording():
    with pytest.raises(ValidationError, match="candidate frames"):
        flockkit.get("builder", "kovar").build(
            flockkit.simulate(n_agents=3, steps=4, seed=0), METRIC, np.random.default_rng(0)
        )


def test_assemble_trims_dead_ends(recording):
    identity = METRIC.compare(recording.configuration(0), recording.configuration(0))
    # 50 -> 100 and 100 -> 50 make a loop through 50..100; 150 -> 200 is a dead end.
    transitions = [(100, 50, identity, 3), (150, 200, identity, 3)]
    graph = flockkit.MotionGraph.assemble(recording, transitions)
    assert list(graph.nodes) == [50, 100] and len(graph.transitions) == 1 and graph.kept_frames() == 51
    with pytest.raises(ValidationError, match="no transitions"):
        flockkit.MotionGraph.assemble(recording, [])


def test_turns_rotate_the_motion_about_the_center_of_mass(recording, graph):
    """Every turn_interval seconds inside the kept recording, two turns (+-turn_angle) that lay the
    same motion, rotated about the group's center of mass, onto it; turn_angle=0 leaves the
    metric's transitions exactly as they were."""
    turns = [t for t in graph.transitions if t.is_turn]
    blend, every = graph.params["blend_frames"], 20  # 2 s at dt 0.1
    frames = sorted({t.start for t in turns})
    assert frames == list(range(int(graph.nodes[0]), int(graph.nodes[-1]) - blend + 1, every))
    for t in turns:
        a = t.alignment
        center = recording.positions[t.start].mean(axis=0)
        assert np.allclose(a.rotation @ center + a.translation, center)  # about the center of mass
        assert np.isclose(abs(np.degrees(np.arctan2(a.rotation[1, 0], a.rotation[0, 0]))), 15.0)
        turned = recording.positions[t.start] @ a.rotation.T + a.translation
        assert np.isclose(a.distance, np.mean(np.sum((turned - recording.positions[t.start]) ** 2, axis=1)))
        assert list(a.assignment) == list(range(recording.n_agents))
    plain = flockkit.get("builder", "kovar", turn_angle=0).build(recording, METRIC, np.random.default_rng(0))

    def frames(transitions):
        return [(t.start, t.end, t.alignment.distance, list(t.alignment.assignment)) for t in transitions]

    assert plain.stats()["turns"] == 0 and frames(plain.transitions) == frames(matched(graph))


def test_turns_in_3d_yaw_and_pitch():
    recording = flockkit.simulate(n_agents=6, steps=160, seed=11, dims=3)
    graph = flockkit.get("builder", "kovar", turn_angle=20).build(recording, METRIC, np.random.default_rng(0))
    turns = [t for t in graph.transitions if t.is_turn]
    assert len(turns) == 4 * len({t.start for t in turns})
    for t in turns:
        r = t.alignment.rotation
        assert np.isclose(np.degrees(np.arccos((np.trace(r) - 1) / 2)), 20.0) and np.isclose(np.linalg.det(r), 1)
        axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
        heading = recording.configuration(t.start).velocities.mean(axis=0)
        # about the up axis (yaw), or about a horizontal axis across the heading (pitch)
        assert np.allclose(axis[:2], 0) or (abs(axis[2]) < 1e-9 and abs(axis[:2] @ heading[:2]) < 1e-9)


def test_a_turn_steers_the_synthesized_group_by_its_angle(graph):
    """Playing a turn: positions continue (no jump), and once its blend has played out the group
    heads turn_angle (15 degrees) away from where the recording heads."""
    turn = next(i for i, t in enumerate(graph.transitions) if t.is_turn and t.start + 60 <= graph.nodes[-1])
    t = graph.transitions[turn]
    blend = t.blend
    walk = flockkit.Walk(
        start=t.source, edges=[("transition", turn)] + [("clip", k) for k in range(t.source, t.source + 4)]
    )
    played = flockkit.synthesize(graph, walk)
    com, source = played.center_of_mass(), graph.motion.center_of_mass()
    assert np.allclose(com[0], source[t.start])
    after = blend + 1  # the blend has played out
    moved, recorded = com[after + 1] - com[after], source[t.start + after + 1] - source[t.start + after]
    angle = np.degrees(np.arctan2(recorded[0] * moved[1] - recorded[1] * moved[0], recorded @ moved))
    assert np.isclose(abs(angle), 15.0)
    steps = np.linalg.norm(np.diff(com, axis=0), axis=1)
    assert steps.max() <= 1.5 * np.linalg.norm(np.diff(source, axis=0), axis=1).max()  # no jump


def test_bridges_join_the_dead_ends_and_add_turned_stretches():
    """bridges=True: the graph keeps frames that trimming dropped, holds solver-made stretches
    (reported in params), and stays the same graph for the same seed."""
    recording = flockkit.simulate(n_agents=6, steps=300, seed=3)
    options = {"blend_time": 1.0, "min_transitions": 10, "bridge_seconds": 3.0, "bridge_turn": 20.0}
    plain = flockkit.build_graph(recording, seed=3, **options)
    bridged = flockkit.build_graph(recording, seed=3, bridges=True, **options)
    first = bridged.params["bridge_frames"]
    assert first == recording.n_frames and bridged.motion.n_frames > first
    assert any(s["made"] for s in bridged.params["bridges"]["stretches"])
    kept = bridged.nodes[bridged.nodes < first]
    assert kept.min() <= plain.nodes.min() and kept.max() >= plain.nodes.max()
    assert bridged.kept_frames() > plain.kept_frames()
    assert flockkit.build_graph(recording, seed=3, bridges=True, **options) == bridged
