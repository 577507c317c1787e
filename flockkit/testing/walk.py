"""Conformance checks for walk strategies (``flockkit.interfaces.WalkStrategy``).

Each check is ``check_<property>(name, strategy, *, graph=None)``; they walk the partner `graph`,
by default the kit's own (``flockkit.testing.inputs.graph``: a group circling the origin, its
transitions exact), which needs no plugin, and the smallest graph there is
(``inputs.loop_graph``: one clip, one transition back). A walk call that runs past
WALK_SECONDS (60 s of wall-clock time; a walk of these small graphs takes well under a second)
fails, so that a walk that loops for ever is reported instead of hanging the suite.
"""

from __future__ import annotations

import numpy as np

from ..errors import FlockkitError
from ..graphs import Walk, synthesize_graph
from ._expect import dims_of, expect_validation_error, fixed_by, needs, on_input, within

WALK_SECONDS = 60.0  # a walk of the kit's graphs that takes longer loops, or nearly so


def _walk(name, strategy, graph, seed, duration):
    with within(WALK_SECONDS, f"{name}.walk(duration={duration}) on a graph of {len(graph.clips)} clips"):
        return strategy.walk(graph, np.random.default_rng(seed), duration)


def _played(name, graph, walk) -> float:
    """Seconds `walk` plays on `graph`; AssertionError when it is no Walk or does not fit."""
    assert isinstance(walk, Walk), f"{name}.walk returned {type(walk).__name__}, not a flockkit.Walk"
    try:
        return synthesize_graph(graph, walk).duration
    except FlockkitError as exc:
        raise AssertionError(
            f"{name}.walk returned a Walk that does not fit the graph: {exc}. Each edge must be one that "
            "graph.allowed_edges(node, frames_since_transition) lists at the node the walk has reached"
        ) from exc


def _graphs(strategy, graph, *, blends=(5,)):
    """The graph given, else the kit's own in every dimension the walk declares (a configured
    walk may declare only some of its kind's dimensions: a region walk those of its region), once
    per blend length in `blends`."""
    if graph is not None:
        return [graph]
    from .inputs import graph as kit_graph

    return [kit_graph(dims=d, blend=b) for d in dims_of(strategy) for b in blends]


@needs("graph")
def check_walk_covers_duration(name, strategy, *, graph=None):
    """walk returns a Walk that fits the graph and plays at least the duration asked for, also on
    the kit's graph with blends of 0 frames (where transitions can follow each other at once: a
    walk must still move on through clips)."""
    for kit_graph in _graphs(strategy, graph, blends=(5, 0)):
        blend = max((t.blend for t in kit_graph.transitions), default=0)
        for duration in (5.0, 30.0):
            with on_input(name, strategy, kit_graph.motion.dims, f"the kit's graph with blends of {blend} frames"):
                played = _played(name, kit_graph, _walk(name, strategy, kit_graph, 1, duration))
            assert played >= duration - 1e-9, f"{name}.walk(duration={duration}) plays only {played} s"


@fixed_by(
    "on a graph with one loop the only walk plays it over and over: let the walk repeat edges (a tabu "
    "list must give way when nothing else is allowed), and where a goal truly cannot be met raise a "
    "flockkit error saying why instead of searching on"
)
def check_walks_a_single_loop(name, strategy):
    """On the smallest graph (``inputs.loop_graph``: one clip of 2.3 s, one transition back) a walk
    of 60 s is made, within WALK_SECONDS, and plays at least 60 s."""
    from .inputs import loop_graph

    for dims in dims_of(strategy):
        graph = loop_graph(dims=dims)
        with on_input(name, strategy, dims, "the kit's single-loop graph"):
            walk = _walk(name, strategy, graph, 3, 60.0)
        played = _played(name, graph, walk)
        assert played >= 60.0 - 1e-9, f"{name}.walk(duration=60) on a single loop plays only {played} s"


@needs("graph")
def check_deterministic(name, strategy, *, graph=None):
    """The same seed gives the same walk (60 s walks, three seeds: an unseeded walk cannot match
    by chance)."""
    for kit_graph in _graphs(strategy, graph):
        for seed in (7, 8, 9):
            first = _walk(name, strategy, kit_graph, seed, 60.0)
            assert first == _walk(name, strategy, kit_graph, seed, 60.0), (
                f"{name}.walk differs for the same seed (in {kit_graph.motion.dims}D)"
            )


@needs("graph")
def check_rejects_bad_duration(name, strategy, *, graph=None):
    """A duration <= 0, and a graph that is not a flockkit.MotionGraph, raise
    flockkit.errors.ValidationError."""
    graph = _graphs(strategy, graph)[0]
    for duration in (0.0, -5.0):
        expect_validation_error(
            lambda duration=duration: strategy.walk(graph, np.random.default_rng(0), duration),
            f"{name}.walk(duration={duration})",
        )
    expect_validation_error(
        lambda: strategy.walk(graph.motion, np.random.default_rng(0), 5.0), f"{name}.walk(a Motion as the graph)"
    )


CHECKS = (check_walk_covers_duration, check_walks_a_single_loop, check_deterministic, check_rejects_bad_duration)
