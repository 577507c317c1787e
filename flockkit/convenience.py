"""The convenience layer: one call for common jobs, taking a `seed` instead of a Generator."""

from __future__ import annotations

import attrs
import numpy as np

from . import graphs
from ._progress import progress_bar
from ._version import __version__
from .errors import ValidationError
from .graphs import MotionGraph
from .interfaces import capabilities
from .mesh import AnimatedMesh, resolve_weld
from .motion import Motion, State, random_flock
from .registry import get, label, require_dims, resolve
from .scene.layers import GraphLayers, check_welds, part_motion, synthesize_layers, walk_layers
from .scene.segmentation import Segmentation, motion_of
from .validate import allocation, integer
from .validate import dims as validate_dims
from .validate import seed as validate_seed

__all__ = ["simulate", "build_graph", "walk", "synthesize", "segment", "build_layers", "default_segmenter"]


def simulate(
    behavior="boids",
    *,
    n_agents: int,
    steps: int,
    dims: int = 2,
    dt: float | None = None,
    seed: int | None = None,
    initial: State | None = None,
    progress: bool = False,
    **params,
) -> Motion:
    """Simulate a flock forward with a behavior model and return its motion (``steps + 1`` frames).

    Parameters
    ----------
    behavior : str or behavior model
        Name of an installed behavior model (``flockkit.available("behavior")``), made with `dt`
        and `params`; or a model instance, used as it is (then `dt` and `params` stay unset).
    n_agents, steps, dims
        Flock size (>= 1), number of steps (>= 1), 2 or 3 dimensions (one the model declares in
        its ``Capabilities.dims``).
    dt : float, optional
        Seconds per step for a model made by name (default 0.1).
    seed : int, optional
        Seeds the ``numpy.random.Generator`` used for the initial flock and the simulation; the
        same seed gives the same motion.
    initial : flockkit.State, optional
        Start here instead of at ``random_flock(n_agents=..., dims=..., rng=...)``.
    progress : bool
        Show a progress bar (tqdm) when the model declares ``Capabilities(progress=True)``.
    **params
        Passed to the behavior model's factory with `dt`, e.g. ``cohesion_weight=2.0``.
    """
    n_agents = integer(n_agents, "n_agents", minimum=1)
    steps = integer(steps, "steps", minimum=1)
    dims = validate_dims(dims)
    if isinstance(behavior, str):
        model = get("behavior", behavior, dt=0.1 if dt is None else dt, **params)
    elif dt is not None:
        raise ValidationError("simulate: dt is for a behavior made by name; a model instance steps its own dt")
    else:
        model = resolve("behavior", behavior, **params)
    require_dims("behavior", model, dims, f"a {dims}D flock", spec=behavior)
    # positions, and as much again for the model's channels (boids: its wander)
    allocation(2 * (steps + 1) * n_agents * dims, f"simulate: {steps + 1} frames of {n_agents} agents in {dims}D")
    rng = np.random.default_rng(validate_seed(seed))
    if initial is not None and not isinstance(initial, State):
        raise ValidationError(f"simulate: initial must be a flockkit.State; got {type(initial).__name__}")
    if initial is None:
        initial = random_flock(n_agents=n_agents, dims=dims, rng=rng)
    elif initial.n_agents != n_agents or initial.dims != dims:
        raise ValidationError(
            f"initial state has {initial.n_agents} agents in {initial.dims}D; expected {n_agents} in {dims}D"
        )
    if not (progress and capabilities(model).progress):
        return model.forward(initial, steps, rng)
    with progress_bar(True, unit="step") as report:
        return model.forward(initial, steps, rng, progress=report)


def build_graph(
    motion: Motion,
    *,
    builder="kovar",
    metric="icp-hungarian",
    metric_params: dict | None = None,
    seed: int | None = None,
    progress: bool = False,
    **params,
) -> MotionGraph:
    """Build a motion graph of `motion` (paper 000 section 4.3).

    `builder` and `metric` are installed names or instances. `params` go to a builder made by
    name (for ``kovar``: ``threshold``, ``blend_time``, ``n_jobs``, ...), `metric_params` to a
    metric made by name (for ``icp-hungarian``: ``velocity_weight``, ...). `progress` shows
    progress bars when the builder declares ``Capabilities(progress=True)``. The graph's
    provenance records both components (names, or class names of instances) and their
    parameters, the flockkit version and the seed.
    """
    if not isinstance(motion, Motion):
        raise ValidationError(f"build_graph needs a flockkit.Motion; got {type(motion).__name__}")
    metric_params = dict(metric_params or {})
    made = resolve("builder", builder, **params)
    measure = resolve("metric", metric, **metric_params)
    for kind, component, spec in (("builder", made, builder), ("metric", measure, metric)):
        require_dims(kind, component, motion.dims, f"a {motion.dims}D motion", spec=spec)
    rng = np.random.default_rng(validate_seed(seed))
    if progress and capabilities(made).progress:
        with progress_bar(True) as report:
            graph = made.build(motion, measure, rng, progress=report)
    else:
        graph = made.build(motion, measure, rng)
    provenance = {
        **graph.provenance,
        "builder": label(builder),
        "builder_params": _plain(params if isinstance(builder, str) else _fields(builder)),
        "metric": label(metric),
        "metric_params": _plain(metric_params if isinstance(metric, str) else _fields(metric)),
        "flockkit": __version__,
        "seed": seed,
    }
    return attrs.evolve(graph, provenance=provenance)


def _fields(instance) -> dict:
    """An attrs instance's fields (its configuration), for provenance; {} for other classes."""
    return attrs.asdict(instance, recurse=False) if attrs.has(type(instance)) else {}


def _plain(params: dict) -> dict:
    """The JSON scalars among `params`, less how the work was run (``n_jobs``): equal graphs
    built with one worker or many have equal provenance."""
    return {k: v for k, v in params.items() if isinstance(v, (int, float, str, bool, type(None))) and k != "n_jobs"}


def walk(graph, *, strategy="random", duration: float | None = None, seed: int | None = None, **params):
    """A walk through `graph` with a walk strategy (an installed name with `params`: ``random``,
    ``region`` with ``region=``; or an instance) covering `duration` seconds (default: the length
    of the graph's source motion): ``flockkit.graphs.walk_graph``. On ``flockkit.GraphLayers`` every part
    is walked on its own, each with its own stream of random numbers from `seed`, giving a
    ``flockkit.LayeredWalk`` (``flockkit.scene.walk_layers``)."""
    if isinstance(graph, GraphLayers):
        return walk_layers(graph, strategy=strategy, duration=duration, seed=seed, **params)
    return graphs.walk_graph(graph, strategy=strategy, duration=duration, seed=seed, **params)


def synthesize(graph, walk) -> Motion:
    """The motion of `walk` through `graph` (``flockkit.graphs.synthesize_graph``); on
    ``flockkit.GraphLayers`` with a ``LayeredWalk``, the whole object from its parts' walks, the
    seams between parts of a mesh smoothed (``flockkit.scene.synthesize_layers``)."""
    if isinstance(graph, GraphLayers):
        return synthesize_layers(graph, walk)
    return graphs.synthesize_graph(graph, walk)


# The segmenters the convenience layer picks where none is named: the skin-aware built-in for a
# mesh that carries a skin, the motion-only one for anything else.
SKIN_SEGMENTER, MOTION_SEGMENTER = "skin-parts", "ica-kmeans"


def default_segmenter(source) -> str:
    """The segmenter ``segment`` and ``build_layers`` use where none is named: ``skin-parts`` for
    an AnimatedMesh with a skin (``AnimatedMesh.skin``: parts follow its joints, so they follow
    anatomy), ``ica-kmeans`` for anything else (parts from motion alone)."""
    return SKIN_SEGMENTER if isinstance(source, AnimatedMesh) and source.skin is not None else MOTION_SEGMENTER


def segment(source, *, segmenter=None, seed: int | None = None, weld=None, **params) -> Segmentation:
    """Split the points of `source` (a Motion, or an AnimatedMesh's vertices) into parts that move
    independently, with `segmenter` (a registered name made with `params`, or an instance).

    `segmenter` None (the default) picks :func:`default_segmenter`: ``skin-parts`` where `source`
    is an AnimatedMesh with a skin (a skinned glTF character), ``ica-kmeans`` otherwise. A
    segmenter declaring ``Capabilities(skin=True)`` is given the mesh's skin; one is refused for
    a source without a skin.

    `weld`: the copies of one surface point (``flockkit.mesh.weld_map``) are segmented as one
    point and get one part. None (the default) welds an AnimatedMesh's vertices that coincide in
    every frame to ``flockkit.mesh.WELD_TOLERANCE`` of its size and leaves a Motion's agents
    alone; False welds nothing; True, or a tolerance (a fraction of the object's size), welds
    either. The labels are one per point of `source`, in its order."""
    motion = motion_of(source)
    spec = default_segmenter(source) if segmenter is None else segmenter
    made = resolve("segmenter", spec, **params)
    require_dims("segmenter", made, motion.dims, f"a {motion.dims}D motion", spec=spec)
    return _segment(made, motion, resolve_weld(source, weld), seed, _skin_for(made, source, spec))


def _skin_for(made, source, spec):
    """The skin to give `made`: the source's where it declares ``Capabilities(skin=True)`` (a
    ValidationError where the source has none), else None."""
    if not capabilities(made).skin:
        return None
    skin = source.skin if isinstance(source, AnimatedMesh) else None
    if skin is None:
        what = "an AnimatedMesh without a skin" if isinstance(source, AnimatedMesh) else "a Motion"
        raise ValidationError(
            f"segmenter {label(spec)} needs a skin (Capabilities.skin) and the source is {what}: segment a skinned "
            f"mesh (flockkit.io.read_mesh_animation of a skinned glTF character), or use a segmenter of motion alone "
            f"such as {MOTION_SEGMENTER!r}"
        )
    return skin


def _segment(made, motion: Motion, welds, seed, skin=None) -> Segmentation:
    """`made`'s segmentation of `motion`, the points welded by `welds` (or None) segmented once,
    given `skin` (the motion's, or None for a segmenter that takes none)."""
    kept = None if welds is None else np.flatnonzero(welds == np.arange(len(welds)))
    segmented = motion if kept is None else Motion(positions=motion.positions[:, kept], dt=motion.dt)
    rng = np.random.default_rng(validate_seed(seed))
    if skin is None:
        result = made.segment(segmented, rng)
    else:
        result = made.segment(segmented, rng, skin=skin if kept is None else skin.take(kept))
    if not isinstance(result, Segmentation):
        raise ValidationError(f"segmenter returned {type(result).__name__}, not a flockkit.Segmentation")
    result.check_fits(segmented, "the (welded) motion")
    if kept is None:
        return result
    return Segmentation(labels=result.labels[np.searchsorted(kept, welds)], n_parts=result.n_parts)


def build_layers(
    source,
    *,
    segmentation: Segmentation | None = None,
    segmenter=None,
    segmenter_params: dict | None = None,
    builder="windowed",
    features=None,
    seed: int | None = None,
    weld=None,
    **params,
) -> GraphLayers:
    """Graph layers of `source` (a Motion, or an AnimatedMesh whose faces are kept for seams): its
    points split by `segmentation` (default: `segmenter` with `segmenter_params`, as for
    :func:`segment`: None picks ``skin-parts`` for a skinned mesh, else ``ica-kmeans``), then one graph
    per part built by `builder` with `params` (as for :func:`flockkit.build_graph`). `features`
    (a ``flockkit.Features`` of the source's frames, e.g. ``Features.from_keyframes`` for a flag
    in the wind or ``Features.from_motion`` for a walking animal) travel with the layers.

    `weld` (as for :func:`segment`; by default a mesh's copies of one point, a triangle soup's
    corners included) welds points for the segmentation and the seams, and synthesis plays every
    copy of a point at one position, so the surface never cracks (``GraphLayers.welds``). A
    given `segmentation` must put welded points in one part."""
    motion = motion_of(source)
    welds = resolve_weld(source, weld)
    if segmentation is None:
        spec = default_segmenter(source) if segmenter is None else segmenter
        made = resolve("segmenter", spec, **dict(segmenter_params or {}))
        require_dims("segmenter", made, motion.dims, f"a {motion.dims}D motion", spec=spec)
        segmentation = _segment(made, motion, welds, seed, _skin_for(made, source, spec))
    elif not isinstance(segmentation, Segmentation):
        raise ValidationError(f"segmentation must be a flockkit.Segmentation; got {type(segmentation).__name__}")
    segmentation.check_fits(motion)
    if welds is not None:
        check_welds(welds, segmentation.labels, "build_layers: segmentation (welded points)")
    graphs = [build_graph(part_motion(motion, points), builder=builder, seed=seed, **params)
              for points in segmentation.parts()]  # fmt: skip
    faces = source.faces if isinstance(source, AnimatedMesh) else None
    return GraphLayers(source=motion, segmentation=segmentation, graphs=graphs, faces=faces, features=features,
                       welds=welds)  # fmt: skip
