"""Conformance checks for walk strategies (``flockkit.interfaces.WalkStrategy``).

Each check is ``check_<property>(name, strategy)``; they walk a graph built once from a boids
recording (2D, centered near the origin) with the installed ``kovar`` builder.
"""

from __future__ import annotations

import functools

import numpy as np

from ..convenience import build_graph, simulate
from ..graph import Walk
from ..synthesis import synthesize
from ._expect import expect_validation_error


@functools.lru_cache(maxsize=1)
def kit_graph():
    """The graph the walk checks use (built once per process)."""
    return build_graph(simulate(n_agents=6, steps=120, seed=11), seed=0)


def check_walk_covers_duration(name, strategy):
    """walk returns a Walk that fits the graph and plays at least the duration asked for."""
    graph = kit_graph()
    for duration in (5.0, 30.0):
        walk = strategy.walk(graph, np.random.default_rng(1), duration)
        assert isinstance(walk, Walk), f"{name}.walk returned {type(walk).__name__}, not a flockkit.Walk"
        motion = synthesize(graph, walk)
        assert motion.duration >= duration - 1e-9, f"{name}.walk(duration={duration}) plays only {motion.duration} s"


def check_deterministic(name, strategy):
    """The same seed gives the same walk (60 s walks, three seeds: an unseeded walk cannot match
    by chance)."""
    graph = kit_graph()
    for seed in (7, 8, 9):
        first = strategy.walk(graph, np.random.default_rng(seed), 60.0)
        assert first == strategy.walk(graph, np.random.default_rng(seed), 60.0), f"{name}.walk differs for the same seed"


def check_rejects_bad_duration(name, strategy):
    """A duration <= 0 raises flockkit.errors.ValidationError."""
    for duration in (0.0, -5.0):
        expect_validation_error(lambda: strategy.walk(kit_graph(), np.random.default_rng(0), duration), f"{name}.walk(duration={duration})")


CHECKS = (check_walk_covers_duration, check_deterministic, check_rejects_bad_duration)
