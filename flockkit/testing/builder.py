"""Conformance checks for graph builders (``flockkit.interfaces.GraphBuilder``).

Each check is ``check_<property>(name, builder)``; they build from a short boids recording with the
installed ``icp-hungarian`` metric.
"""

from __future__ import annotations

import numpy as np

from ..convenience import simulate
from ..graph import MotionGraph
from ..registry import get
from ._expect import expect_validation_error


def _recording():
    return simulate(n_agents=6, steps=120, seed=11)


def _build(builder, motion=None):
    motion = _recording() if motion is None else motion
    return motion, builder.build(motion, get("metric", "icp-hungarian"), np.random.default_rng(0))


def _structure(graph):
    return list(graph.nodes), graph.clips, graph.transitions


def check_build_returns_graph(name, builder):
    """build returns a MotionGraph over the given motion, with at least one transition."""
    motion, graph = _build(builder)
    assert isinstance(graph, MotionGraph), f"{name}.build returned {type(graph).__name__}, not a flockkit.MotionGraph"
    assert graph.motion == motion, f"{name}.build returned a graph over another motion"
    assert graph.transitions, f"{name}.build returned a graph without transitions"


def _reached(graph, forward: bool) -> set[int]:
    edges = [(c.source, c.target) for c in graph.clips] + [(t.source, t.target) for t in graph.transitions]
    if not forward:
        edges = [(b, a) for a, b in edges]
    seen, frontier = {0}, [0]
    while frontier:
        node = frontier.pop()
        for a, b in edges:
            if a == node and b not in seen:
                seen.add(b)
                frontier.append(b)
    return seen


def check_strongly_connected(name, builder):
    """Every node reaches every other: no dead ends for a walk."""
    _, graph = _build(builder)
    every = set(range(len(graph.nodes)))
    assert _reached(graph, True) == every and _reached(graph, False) == every, f"{name}.build left dead ends in the graph"


def check_transitions_align(name, builder):
    """Each transition's alignment lays the end configuration onto the start one as well as it says."""
    motion, graph = _build(builder)
    for t in graph.transitions:
        a, b = motion.configuration(t.start), motion.configuration(t.end)
        residual = t.alignment.residual(a, b)
        scale = max(1.0, float(np.mean(np.sum((a.positions - a.center_of_mass()) ** 2, axis=1))))
        assert residual <= t.alignment.distance + 1e-9 * scale, (
            f"{name}: the transition {t.start} -> {t.end} claims distance {t.alignment.distance} but leaves {residual}"
        )


def check_deterministic(name, builder):
    """The same motion and seed give the same graph."""
    motion = _recording()
    first, second = _build(builder, motion)[1], _build(builder, motion)[1]
    assert _structure(first) == _structure(second), f"{name}.build gives different graphs for the same input"


def check_inputs_unchanged(name, builder):
    """build leaves the motion as it was."""
    motion = _recording()
    before = motion.positions.copy()
    _build(builder, motion)
    assert np.array_equal(before, motion.positions), f"{name}.build changed its motion"


def check_rejects_bad_motion(name, builder):
    """Something that is not a Motion raises flockkit.errors.ValidationError."""
    expect_validation_error(
        lambda: builder.build(np.zeros((10, 3, 2)), get("metric", "icp-hungarian"), np.random.default_rng(0)),
        f"{name}.build(array)",
    )


CHECKS = (
    check_build_returns_graph,
    check_strongly_connected,
    check_transitions_align,
    check_deterministic,
    check_inputs_unchanged,
    check_rejects_bad_motion,
)
