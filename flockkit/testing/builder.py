"""Conformance checks for graph builders (``flockkit.interfaces.GraphBuilder``).

Each check is ``check_<property>(name, builder, *, metric=None)``; they build from the kit's own
recording (``flockkit.testing.inputs.recording``, in the builder's first declared dimension) with
the partner `metric` (default: the built-in ``icp-hungarian``, where installed).
"""

from __future__ import annotations

import numpy as np

from ..graphs import MotionGraph
from ._expect import applies_when, dims_of, expect_validation_error, needs, partner
from .inputs import recording


def _recording(builder):
    return recording(n_agents=6, seconds=12.0, dims=dims_of(builder)[0], seed=11)


def _build(builder, metric, motion=None, **options):
    motion = _recording(builder) if motion is None else motion
    return motion, builder.build(motion, partner(metric, "metric", "builder"), np.random.default_rng(0), **options)


def _structure(graph):
    return list(graph.nodes), graph.clips, graph.transitions


@needs("metric")
def check_build_returns_graph(name, builder, *, metric=None):
    """build returns a MotionGraph over the given motion, with at least one transition."""
    motion, graph = _build(builder, metric)
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


@needs("metric")
def check_strongly_connected(name, builder, *, metric=None):
    """Every node reaches every other: no dead ends for a walk."""
    _, graph = _build(builder, metric)
    every = set(range(len(graph.nodes)))
    assert _reached(graph, True) == every and _reached(graph, False) == every, (
        f"{name}.build left dead ends in the graph"
    )


@needs("metric")
def check_transitions_align(name, builder, *, metric=None):
    """Each transition's alignment lays the end configuration onto the start one as well as it says."""
    motion, graph = _build(builder, metric)
    for t in graph.transitions:
        a, b = motion.configuration(t.start), motion.configuration(t.end)
        residual = t.alignment.residual(a, b)
        scale = max(1.0, float(np.mean(np.sum((a.positions - a.center_of_mass()) ** 2, axis=1))))
        assert residual <= t.alignment.distance + 1e-9 * scale, (
            f"{name}: the transition {t.start} -> {t.end} claims distance {t.alignment.distance} but leaves {residual}"
        )


@needs("metric")
def check_deterministic(name, builder, *, metric=None):
    """The same motion and seed give the same graph."""
    motion = _recording(builder)
    first, second = _build(builder, metric, motion)[1], _build(builder, metric, motion)[1]
    assert _structure(first) == _structure(second), f"{name}.build gives different graphs for the same input"


@needs("metric")
def check_inputs_unchanged(name, builder, *, metric=None):
    """build leaves the motion as it was."""
    motion = _recording(builder)
    before = motion.positions.copy()
    _build(builder, metric, motion)
    assert np.array_equal(before, motion.positions), f"{name}.build changed its motion"


@needs("metric")
def check_rejects_bad_motion(name, builder, *, metric=None):
    """Something that is not a Motion raises flockkit.errors.ValidationError."""
    expect_validation_error(
        lambda: builder.build(np.zeros((10, 3, 2)), partner(metric, "metric", "builder"), np.random.default_rng(0)),
        f"{name}.build(array)",
    )


@applies_when("progress")
@needs("metric")
def check_progress(name, builder, *, metric=None):
    """A builder declaring ``progress`` reports (done, total, stage) within each stage, and builds
    the same graph as without a report."""
    calls = []
    _, reported = _build(builder, metric, progress=lambda *args: calls.append(args))
    assert calls, f"{name}.build(progress=...) never called progress"
    for done, total, stage in calls:
        assert isinstance(stage, str) and 0 <= done <= total, (
            f"{name}: progress({done}, {total}, {stage!r}) is not a count of a total"
        )
    assert _structure(reported) == _structure(_build(builder, metric)[1]), (
        f"{name} builds another graph when it reports progress"
    )


CHECKS = (
    check_build_returns_graph,
    check_strongly_connected,
    check_transitions_align,
    check_deterministic,
    check_inputs_unchanged,
    check_rejects_bad_motion,
    check_progress,
)
