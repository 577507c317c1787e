"""Playback of walks through a motion graph (paper 000 section 5).

A walk becomes segments: a range of source frames played with a rigid placement (source to world)
and a correspondence (output agent k plays source agent ``M[k]``). A clip plays its frames except
the last, which the next edge starts from. A transition at source frame s to source frame e,
with alignment A (``config(s) ~= A.rotation @ config(e)[A.assignment] + A.translation``), composes
the placement with A, so world positions continue, and maps the correspondence through
``A.assignment``, so every output agent keeps one identity: M' = A.assignment[M]. For the
transition's `blend` frames the old motion (source frames s, s + 1, ...) is blended into the new
one with a smoothstep weight, so there is no jump in position or velocity.

Per frame the work is array gathers; Python loops run over segments, never over agents.
"""

from __future__ import annotations

import numpy as np

from .errors import ValidationError
from .graph import MotionGraph, Walk
from .motion import Motion

__all__ = ["synthesize", "synthesize_many"]


def _smoothstep(u: np.ndarray) -> np.ndarray:
    return u * u * (3.0 - 2.0 * u)


def _plan(graph: MotionGraph, walk: Walk):
    """Segments (frames, rotation, translation, correspondence) and blends (output start, old
    segment) of `walk`, checked against `graph`."""
    if not isinstance(walk, Walk):
        raise ValidationError(f"synthesize needs a flockkit.Walk; got {type(walk).__name__}")
    if not 0 <= walk.start < len(graph.nodes):
        raise ValidationError(f"Walk.start {walk.start} is not a node of this graph (0..{len(graph.nodes) - 1})")
    rotation, translation = walk.pose(graph.motion.dims)
    mapping = np.arange(graph.motion.n_agents)
    node, since, length = walk.start, np.inf, 0
    segments, blends = [], []
    for position, (kind, index) in enumerate(walk.edges):
        edges = graph.clips if kind == "clip" else graph.transitions
        if index >= len(edges) or edges[index].source != node:
            raise ValidationError(f"Walk.edges[{position}] = {(kind, index)!r} does not leave node {node}")
        edge = edges[index]
        if kind == "clip":
            frames = np.arange(edge.start, edge.stop)
            segments.append((frames, rotation, translation, mapping))
            since += len(frames)
            length += len(frames)
        else:
            if since < edge.blend:
                raise ValidationError(
                    f"Walk.edges[{position}] takes a transition {since} frames after the previous one; "
                    f"its blend needs {edge.blend}"
                )
            old = (np.arange(edge.start, edge.start + edge.blend), rotation, translation, mapping)
            blends.append((length, old))
            a = edge.alignment
            rotation, translation = rotation @ a.rotation, rotation @ a.translation + translation
            mapping = a.assignment[mapping]
            since = 0
        node = edge.target
    segments.append((np.array([graph.nodes[node]]), rotation, translation, mapping))
    return segments, blends


def _place(source: np.ndarray, segment) -> np.ndarray:
    frames, rotation, translation, mapping = segment
    return source[frames][:, mapping] @ rotation.T + translation


def _positions(graph: MotionGraph, walk: Walk) -> np.ndarray:
    source = graph.motion.positions
    segments, blends = _plan(graph, walk)
    positions = np.concatenate([_place(source, segment) for segment in segments], axis=0)
    for start, old in blends:
        count = min(len(old[0]), len(positions) - start)
        if count <= 0:
            continue
        weight = _smoothstep(np.arange(1, count + 1) / (len(old[0]) + 1))[:, None, None]
        old_frames = (old[0][:count], *old[1:])
        positions[start : start + count] = (1 - weight) * _place(source, old_frames) + weight * positions[start : start + count]
    return positions


def synthesize(graph: MotionGraph, walk: Walk) -> Motion:
    """The motion of `walk` through `graph`: one Motion of the graph's agents, at the source dt.

    Raises ValidationError if the walk does not fit the graph (an edge that does not leave the
    node reached, or a transition taken before the previous blend has played out).
    """
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"synthesize needs a flockkit.MotionGraph; got {type(graph).__name__}")
    return Motion(positions=_positions(graph, walk), dt=graph.motion.dt)


def synthesize_many(graph: MotionGraph, walks, *, n_frames: int | None = None) -> Motion:
    """Many independent walks in one Motion: walk w's agents are agents ``w * N .. (w + 1) * N - 1``.

    All are cut to `n_frames` (default: the shortest walk's length), so a crowd of flocks shares
    one timeline.
    """
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"synthesize_many needs a flockkit.MotionGraph; got {type(graph).__name__}")
    walks = list(walks)
    if not walks:
        raise ValidationError("synthesize_many needs at least one walk")
    played = [_positions(graph, walk) for walk in walks]
    shortest = min(len(p) for p in played)
    if n_frames is None:
        n_frames = shortest
    elif isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or not 1 <= n_frames <= shortest:
        raise ValidationError(f"n_frames must be an integer in 1..{shortest} (the shortest walk); got {n_frames!r}")
    return Motion(positions=np.concatenate([p[:n_frames] for p in played], axis=1), dt=graph.motion.dt)
