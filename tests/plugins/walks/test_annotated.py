"""The annotated walk (paper 002, section 6.1) on plain graphs: it follows the target, reports
its energy, and refuses targets its source cannot approach."""

import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError
from flockkit.testing import inputs


def test_the_energy_reported_is_the_papers_sum_over_the_walk():
    graph = inputs.graph()
    strategy = flockkit.get("walk", "annotated", target=[(0.0, [1.0, 0.0]), (20.0, [0.0, -1.0])], alpha=3, beta=2)
    walk = strategy.walk(graph, np.random.default_rng(3), 40.0)
    energy = strategy.energy(graph, walk, 40.0)
    taken = [index for kind, index in walk.edges if kind == "transition"]
    assert energy["N_T"] == len(taken) > 0
    scale = np.median([t.alignment.distance for t in graph.transitions if not t.is_turn])
    assert energy["C_T"] == pytest.approx(sum(graph.transitions[i].alignment.distance for i in taken) / scale)
    frames, rotations = flockkit.graphs.played_frames(graph, walk)
    played = np.einsum("fij,fj->fi", rotations, flockkit.Features.from_motion(graph.motion).vectors[frames])[:400]
    target = flockkit.scene.interpolate_arrows(
        np.array([0.0, 20.0]), np.array([[1.0, 0], [0, -1.0]]), np.arange(400) * 0.1
    )
    assert energy["C_C"] == pytest.approx(np.linalg.norm(played - target, axis=1).sum() * 0.1)
    assert energy["E"] == pytest.approx(energy["C_T"] + 3 * energy["C_C"] + 2 * energy["N_T"])


def test_a_target_the_source_cannot_approach_is_refused_in_numbers():
    motion, labels, wind = inputs.plants()
    graph = flockkit.build_graph(motion, builder="windowed", seed=0)
    strategy = flockkit.get("walk", "annotated", target=[(0.0, [0.0, 0.0, 1.0])], features=wind)
    with pytest.raises(ValidationError, match=r"is 1.\d+ from the closest arrow the graph plays"):
        strategy.walk(graph, np.random.default_rng(0), 5.0)


def test_bad_parameters_are_named():
    with pytest.raises(ValidationError, match="target"):
        flockkit.get("walk", "annotated", target="wind")
    with pytest.raises(ValidationError, match="must increase"):
        flockkit.get("walk", "annotated", target=[(1.0, [1.0, 0.0]), (0.0, [0.0, 1.0])])
    with pytest.raises(ValidationError, match="alpha"):
        flockkit.get("walk", "annotated", target=[(0.0, [1.0, 0.0])], alpha=-1)


def test_arrows_only_in_frames_the_graph_dropped_are_out_of_reach():
    graph = inputs.graph()  # keeps source frames 0..113 of 121
    arrows = flockkit.Features.from_motion(graph.motion).vectors.copy()
    arrows[graph.nodes[-1] + 1 :] = [0.0, 0.1]  # a slow drift, only where no walk can go
    features = flockkit.Features(vectors=arrows, dt=graph.motion.dt)
    strategy = flockkit.get("walk", "annotated", target=[(0.0, [0.0, 0.1])], features=features, reach=0.3)
    with pytest.raises(
        ValidationError, match=r"closest arrow the graph plays .* at source frame (\d{1,2}|10\d|11[0-3])\)"
    ):
        strategy.walk(graph, np.random.default_rng(0), 5.0)


@pytest.mark.parametrize("avoiding", [False, True])
@pytest.mark.parametrize("source", ["cycle", "plants"])
def test_walks_from_the_error_tables_equal_walks_that_compute_every_error(monkeypatch, source, avoiding):
    """The per-walk tables of frame errors (graphs that do not turn) give the very walks that
    computing each error from the arrows gives: a looping cycle with phase shifts and a recording
    of plants in a turning wind, a ramping target, with walks to avoid (rows of -1 among them)."""
    from flockkit_walks import annotated

    if source == "cycle":
        phase = 2 * np.pi * np.arange(30)[:, None] / 30
        s = np.linspace(0.2, 1.0, 5)[None, :]
        motion = flockkit.Motion(positions=np.stack(np.broadcast_arrays(s, 0 * s, 0.4 * s * np.sin(phase + s)), axis=2),
                                 dt=1 / 30)  # fmt: skip
        features = flockkit.Features.from_keyframes([[0, [0.3, 0]], [0.5, [0.6, 0.1]], [0.9, [0.3, 0]]],
                                                    n_frames=30, dt=1 / 30)  # fmt: skip
    else:
        motion, _, features = inputs.plants(dt=1 / 30, seconds=24.0, points=40, rates=(1.5, 3.0))
    graph = flockkit.build_graph(motion, builder="windowed")
    target = [[0, [0.4, 0]], [10, [0.6, 0.05]], [20, [0.35, 0]]]
    rng = np.random.default_rng(5)
    frames = round(20 / motion.dt)
    avoid = None
    if avoiding:
        avoid = rng.integers(0, motion.n_frames if graph.period is None else graph.period, (3, frames))
        avoid[2] = -1

    def no_tables(problem):  # every error computed from the arrows, in Python
        problem.error_table = problem.step_table = None
        problem.compiled = False

    walks = []
    for tables in (True, False):
        if not tables:
            monkeypatch.setattr(annotated._Problem, "_tables", no_tables)
        strategy = flockkit.get("walk", "annotated", target=target, features=features, avoid=avoid)
        walks.append([strategy.walk(graph, np.random.default_rng(seed), 20.0) for seed in range(3)])
    assert walks[0] == walks[1]
    assert any(kind == "transition" for w in walks[0] for kind, _ in w.edges)  # choices were made


def test_transition_costs_keep_their_unit_where_most_ordinary_transitions_cost_nothing():
    """C_T divides each transition's distance by the median ordinary distance; where most are 0 (a
    looping source's exact repeats) the unit is the median of those above 0, so a transition that
    does differ still costs what it differs instead of nothing."""
    import attrs
    from flockkit_walks import annotated

    motion, _, _ = inputs.plants(dt=1 / 10, seconds=24.0, points=8, rates=(1.5, 3.0))
    graph = flockkit.build_graph(motion, builder="kovar")
    ordinary = [k for k, t in enumerate(graph.transitions) if not t.is_turn and not graph.shifts[k]]
    assert len(ordinary) >= 3
    paid = ordinary[: max(1, len(ordinary) // 3)]  # a third differ, the rest repeat exactly
    distances = {k: 0.5 + k for k in paid}
    transitions = [
        attrs.evolve(t, alignment=attrs.evolve(t.alignment, distance=distances.get(k, 0.0)))
        for k, t in enumerate(graph.transitions)
    ]
    costs = annotated._Shared(attrs.evolve(graph, transitions=transitions), beta=1.0).trans_cost
    unit = np.median(list(distances.values()))
    np.testing.assert_allclose(costs[paid], [distances[k] / unit for k in paid])
    assert np.all(costs[[k for k in ordinary if k not in distances]] == 0)
