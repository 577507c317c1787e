"""Conformance checks for walk strategies (``flockkit.interfaces.WalkStrategy``).

Each check is ``check_<property>(name, strategy, *, graph=None)``; they walk the partner `graph`,
by default the kit's own (``flockkit.testing.inputs.graph``: a group circling the origin, its
transitions exact), which needs no plugin.
"""

from __future__ import annotations

import numpy as np

from ..graphs import Walk, synthesize_graph
from ._expect import dims_of, expect_validation_error, needs


def _graph(strategy, graph):
    if graph is not None:
        return graph
    from .inputs import graph as kit_graph

    return kit_graph(dims=dims_of(strategy)[0])


@needs("graph")
def check_walk_covers_duration(name, strategy, *, graph=None):
    """walk returns a Walk that fits the graph and plays at least the duration asked for."""
    graph = _graph(strategy, graph)
    for duration in (5.0, 30.0):
        walk = strategy.walk(graph, np.random.default_rng(1), duration)
        assert isinstance(walk, Walk), f"{name}.walk returned {type(walk).__name__}, not a flockkit.Walk"
        motion = synthesize_graph(graph, walk)
        assert motion.duration >= duration - 1e-9, f"{name}.walk(duration={duration}) plays only {motion.duration} s"


@needs("graph")
def check_deterministic(name, strategy, *, graph=None):
    """The same seed gives the same walk (60 s walks, three seeds: an unseeded walk cannot match
    by chance)."""
    graph = _graph(strategy, graph)
    for seed in (7, 8, 9):
        first = strategy.walk(graph, np.random.default_rng(seed), 60.0)
        assert first == strategy.walk(graph, np.random.default_rng(seed), 60.0), (
            f"{name}.walk differs for the same seed"
        )


@needs("graph")
def check_rejects_bad_duration(name, strategy, *, graph=None):
    """A duration <= 0 raises flockkit.errors.ValidationError."""
    graph = _graph(strategy, graph)
    for duration in (0.0, -5.0):
        expect_validation_error(
            lambda duration=duration: strategy.walk(graph, np.random.default_rng(0), duration),
            f"{name}.walk(duration={duration})",
        )


CHECKS = (check_walk_covers_duration, check_deterministic, check_rejects_bad_duration)
