"""The convenience layer: one call for common jobs, taking a `seed` instead of a Generator."""

from __future__ import annotations

import inspect
import math

import attrs

import numpy as np

from ._arrays import count, positive_number
from .errors import ValidationError
from .graph import MotionGraph, Walk
from .motion import Motion, State
from .registry import get

__all__ = ["simulate", "random_flock", "build_graph", "walk"]


def random_flock(*, n_agents: int, dims: int = 2, rng: np.random.Generator, spacing: float = 1.0, speed: float = 1.0) -> State:
    """A random flock, the documented start of :func:`simulate`.

    Positions are uniform in a disc (2D) or ball (3D) around the origin whose area (volume) is
    ``n_agents * spacing**dims``, so neighbors are about `spacing` apart. All agents head roughly
    the same way: a common direction, uniform at random, plus independent Gaussian noise of
    standard deviation 0.2 per component, normalized and scaled to `speed`. No model arrays
    (``extra`` is empty), so a model starts its own (boids: zero wander).
    """
    n_agents = count(n_agents, field="n_agents")
    if dims not in (2, 3):
        raise ValidationError(f"dims must be 2 or 3; got {dims!r}")
    spacing = positive_number(spacing, field="spacing")
    speed = positive_number(speed, field="speed")
    unit_ball = math.pi if dims == 2 else 4.0 * math.pi / 3.0
    radius = spacing * (n_agents / unit_ball) ** (1.0 / dims)
    directions = rng.standard_normal((n_agents, dims))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    positions = directions * radius * rng.random((n_agents, 1)) ** (1.0 / dims)
    heading = rng.standard_normal(dims)
    heading /= np.linalg.norm(heading)
    headings = heading + 0.2 * rng.standard_normal((n_agents, dims))
    velocities = speed * headings / np.linalg.norm(headings, axis=1, keepdims=True)
    return State(positions=positions, velocities=velocities)


def simulate(
    behavior: str = "boids",
    *,
    n_agents: int,
    steps: int,
    dims: int = 2,
    dt: float = 0.1,
    seed: int | None = None,
    initial: State | None = None,
    progress: bool = False,
    **params,
) -> Motion:
    """Simulate a flock forward with a behavior model and return its motion (``steps + 1`` frames).

    Parameters
    ----------
    behavior : str
        Name of an installed behavior model (``flockkit.available("behavior")``).
    n_agents, steps, dims, dt
        Flock size (>= 1), number of steps (>= 1), 2 or 3 dimensions, seconds per step.
    seed : int, optional
        Seeds the ``numpy.random.Generator`` used for the initial flock and the simulation; the
        same seed gives the same motion.
    initial : flockkit.State, optional
        Start here instead of at ``random_flock(n_agents=..., dims=..., rng=...)``.
    progress : bool
        Show a progress bar (tqdm) when the model reports progress.
    **params
        Passed to the behavior model's factory with `dt`, e.g. ``cohesion_weight=2.0``.
    """
    n_agents = count(n_agents, field="n_agents")
    steps = count(steps, field="steps")
    if dims not in (2, 3):
        raise ValidationError(f"dims must be 2 or 3; got {dims!r}")
    model = get("behavior", behavior, dt=dt, **params)
    rng = np.random.default_rng(seed)
    if initial is None:
        initial = random_flock(n_agents=n_agents, dims=dims, rng=rng)
    elif initial.n_agents != n_agents or initial.dims != dims:
        raise ValidationError(
            f"initial state has {initial.n_agents} agents in {initial.dims}D; expected {n_agents} in {dims}D"
        )
    if not progress or "progress" not in inspect.signature(model.forward).parameters:
        return model.forward(initial, steps, rng)
    from tqdm.auto import tqdm

    with tqdm(total=steps, unit="step", desc=f"simulating {n_agents} agents") as bar:
        return model.forward(initial, steps, rng, progress=lambda done: bar.update(done - bar.n))


def build_graph(
    motion: Motion,
    *,
    builder: str = "kovar",
    metric: str = "icp-hungarian",
    metric_params: dict | None = None,
    seed: int | None = None,
    **params,
) -> MotionGraph:
    """Build a motion graph of `motion` (paper 000 section 4.3).

    `params` go to the builder (for ``kovar``: ``threshold``, ``blend_time``, ``n_jobs``, ...),
    `metric_params` to the metric (for ``icp-hungarian``: ``velocity_weight``, ...). The graph's
    provenance records both names and parameters, the flockkit version and the seed.
    """
    if not isinstance(motion, Motion):
        raise ValidationError(f"build_graph needs a flockkit.Motion; got {type(motion).__name__}")
    metric_params = dict(metric_params or {})
    graph = get("builder", builder, **params).build(motion, get("metric", metric, **metric_params), np.random.default_rng(seed))
    from . import __version__

    provenance = {
        **graph.provenance,
        "builder": builder,
        "builder_params": {k: v for k, v in params.items() if isinstance(v, (int, float, str, bool, type(None)))},
        "metric": metric,
        "metric_params": {k: v for k, v in metric_params.items() if isinstance(v, (int, float, str, bool, type(None)))},
        "flockkit": __version__,
        "seed": seed,
    }
    return attrs.evolve(graph, provenance=provenance)


def walk(graph: MotionGraph, *, strategy: str = "random", duration: float | None = None, seed: int | None = None, **params) -> Walk:
    """A walk through `graph` with a walk strategy (``random``; ``region`` with ``region=``)
    covering `duration` seconds (default: the length of the graph's source motion)."""
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"walk needs a flockkit.MotionGraph; got {type(graph).__name__}")
    duration = graph.motion.duration if duration is None else duration
    return get("walk", strategy, **params).walk(graph, np.random.default_rng(seed), duration)
