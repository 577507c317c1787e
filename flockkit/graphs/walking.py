"""Walking motion graphs (paper 000, section 5): one graph with a walk strategy, or the graphs of
an object's parts, each on its own with its own stream of random numbers (paper 002's
asynchronous transitions)."""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError
from ..registry import require_dims, resolve
from ..validate import allocation, number
from ..validate import seed as validate_seed
from .graph import MotionGraph, Walk

__all__ = ["walk_graph", "walk_parts", "part_seeds"]


def walk_graph(graph: MotionGraph, *, strategy="random", duration: float | None = None, seed: int | None = None,
         **params) -> Walk:  # fmt: skip
    """A walk through `graph` with a walk strategy (an installed name with `params`: ``random``,
    ``region`` with ``region=``; or an instance) covering `duration` seconds (default: the length
    of the graph's source motion)."""
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"walk needs a flockkit.MotionGraph; got {type(graph).__name__}")
    duration = graph.motion.duration if duration is None else number(duration, "walk: duration", minimum=0, strict=True)
    made = resolve("walk", strategy, **params)
    require_dims("walk", made, graph.motion.dims, f"a {graph.motion.dims}D graph", spec=strategy)
    frames = duration / graph.motion.dt
    # synthesis holds the positions, their gather indices and placed copies: about 4 times them
    allocation(
        4 * frames * graph.motion.n_agents * graph.motion.dims, f"walk: {duration:g} s ({frames:.3g} frames) of motion"
    )
    return made.walk(graph, np.random.default_rng(validate_seed(seed)), duration)


def part_seeds(seed: int | None, parts: int) -> list[int]:
    """The seed of each of `parts` parts walked from `seed`: independent streams
    (``numpy.random.SeedSequence(seed).spawn``), the same for the same seed."""
    return [int(stream.generate_state(1)[0]) for stream in np.random.SeedSequence(validate_seed(seed)).spawn(parts)]


def walk_parts(graphs, *, strategy="random", duration: float, seed: int | None = None, part_params=None,
               **params) -> list[Walk]:  # fmt: skip
    """A walk through each of `graphs` (an object's parts), each part on its own with its own
    seed (:func:`part_seeds`), with `params` and the part's own `part_params[k]` (a dict each,
    optional)."""
    graphs = list(graphs)
    part_params = [{}] * len(graphs) if part_params is None else list(part_params)
    return [
        walk_graph(graph, strategy=strategy, duration=duration, seed=part_seed, **params, **own)
        for graph, part_seed, own in zip(graphs, part_seeds(seed, len(graphs)), part_params)
    ]
