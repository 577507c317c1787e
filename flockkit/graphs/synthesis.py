"""Playback of walks through a motion graph (paper 000 section 5).

A walk becomes segments: a range of source frames played with a rigid placement (source to world)
and a correspondence (output agent k plays source agent ``M[k]``). A clip plays its frames except
the last, which the next edge starts from. A transition at source frame s to source frame e,
with alignment A (``config(s) ~= A.rotation @ config(e)[A.assignment] + A.translation``), composes
the placement with A, so world positions continue, and maps the correspondence through
``A.assignment``, so every output agent keeps one identity: M' = A.assignment[M]. For the
transition's `blend` frames the old motion (source frames s, s + 1, ...) is blended into the new
one with a smoothstep weight, so there is no jump in position or velocity. On a looping graph
(``MotionGraph.period``) frames run on across the loop: frame ``period + f`` is frame f, for the
motion played and for the motion a blend leaves alike.

All frames are placed at once (one flat gather and a rotation applied component by component);
the only Python loop composes placements, one step per transition taken.
"""

from __future__ import annotations

import numpy as np

from .. import rigid
from ..errors import ValidationError
from ..motion import Motion
from .graph import MotionGraph, Walk

__all__ = [
    "synthesize_graph",
    "synthesize_many",
    "played_positions",
    "played_length",
    "played_frames",
    "blended_frames",
]


def _smoothstep(u: np.ndarray) -> np.ndarray:
    return u * u * (3.0 - 2.0 * u)


def _plan(graph: MotionGraph, walk: Walk, *, placed: bool = True):
    """Lay `walk` out over `graph`: per segment (a stretch between transitions) its output start,
    source start and length, and its rotation, translation and correspondence (None for each
    unless `placed`: composing them is a step per transition); per transition taken, where its
    blend starts in the output, its source frame, the segment it leaves and its blend length."""
    tables = graph.tables
    is_transition, clip_index, transition_index = _edges(graph, walk)
    # A graph of one node (a transition looping on it) has no clips at all.
    clip_start = tables.clip_start[clip_index] if len(graph.clips) else np.zeros(len(clip_index), dtype=np.int64)
    played = np.where(is_transition, 0, tables.clip_stop[clip_index] - clip_start if len(graph.clips) else 0)
    before = np.cumsum(played) - played  # output frames played before each edge
    segment = np.cumsum(is_transition) - is_transition  # segment each edge starts in
    at = np.flatnonzero(is_transition)
    taken = transition_index[at]
    blend = tables.transition_blend[taken]
    since = np.diff(np.concatenate([[-np.inf], before[at]]))  # clip frames since the previous transition
    previous = np.concatenate([[0], blend[:-1]])  # the blend that must have played out
    if np.any(since < previous):
        first = int(np.argmax(since < previous))
        raise ValidationError(
            f"Walk.edges[{int(at[first])}] takes a transition {int(since[first])} frames after the previous one, "
            f"whose blend needs {int(previous[first])}"
        )
    rotations = translations = mappings = None
    if placed:
        rotations, translations, mappings = _compose(walk, tables, taken, graph.motion.n_agents, graph.motion.dims)
    else:
        walk.pose(graph.motion.dims)  # refused as synthesize refuses it
    # A segment (the stretch between two transitions) starts at a node and plays consecutive
    # clips, so it is one slice of the source from that node's frame.
    output_start = np.append(0, before[at])
    length = np.diff(np.append(output_start, played.sum() + 1))  # the last one also plays the final frame
    source_start = graph.nodes[np.append(walk.start, tables.transition_target[taken])]
    blends = (before[at], tables.transition_start[taken], segment[at], blend)
    return (output_start, source_start, length), rotations, translations, mappings, blends


def _edges(graph: MotionGraph, walk: Walk):
    """Check that `walk` is a chain of edges of `graph` from its start node: (is_transition, clip
    index, transition index) per edge, the index of the other kind 0."""
    if not isinstance(walk, Walk):
        raise ValidationError(f"synthesize needs a flockkit.Walk; got {type(walk).__name__}")
    if not 0 <= walk.start < len(graph.nodes):
        raise ValidationError(f"Walk.start {walk.start} is not a node of this graph (0..{len(graph.nodes) - 1})")
    tables = graph.tables
    is_transition, index = walk.edge_arrays
    counts = np.where(is_transition, len(graph.transitions), len(graph.clips))
    if np.any(index >= counts):
        bad = int(np.argmax(index >= counts))
        raise ValidationError(f"Walk.edges[{bad}] = {walk.edges[bad]!r} is not an edge of this graph")
    clip_index = np.where(is_transition, 0, index)
    transition_index = np.where(is_transition, index, 0)
    sources = np.where(is_transition, tables.transition_source[transition_index], clip_index)
    clip_target = tables.clip_target[clip_index] if len(graph.clips) else clip_index + 1
    targets = np.where(is_transition, tables.transition_target[transition_index], clip_target)
    reached = np.concatenate([[walk.start], targets[:-1]])
    if np.any(sources != reached):
        bad = int(np.argmax(sources != reached))
        raise ValidationError(f"Walk.edges[{bad}] = {walk.edges[bad]!r} does not leave node {int(reached[bad])}")
    return is_transition, clip_index, transition_index


def _compose(walk, tables, taken, n_agents, dims):
    """Placement and correspondence of each segment: the start pose composed with the
    transitions taken, in order (M' = assignment[M])."""
    mappings = np.empty((len(taken) + 1, n_agents), dtype=np.int64)
    mappings[0] = np.arange(n_agents)
    for step, transition in enumerate(taken, 1):
        mappings[step] = tables.assignment[transition][mappings[step - 1]]
    rotations, translations = rigid.chain(walk.pose(dims), tables.rotation[taken], tables.translation[taken])
    return rotations, translations, mappings


def _place(source, frames, segments, rotations, translations, mappings) -> np.ndarray:
    """Source frames placed in the world: a flat gather, then each frame's segment placement
    (skipped where every placement is the identity, as for graphs of objects that stay in place)."""
    t, n, d = source.shape
    if np.array_equal(mappings, np.broadcast_to(np.arange(n), mappings.shape)):
        gathered = np.take(source, frames, axis=0)
    else:
        flat = source.reshape(t * n, d)
        index = np.take(mappings, segments, axis=0)
        index += (frames * n)[:, None]
        gathered = np.take(flat, index.ravel(), axis=0).reshape(len(frames), n, d)  # take: much faster than [ ]
    if not np.any(translations) and np.array_equal(rotations, np.broadcast_to(np.eye(d), rotations.shape)):
        return gathered
    return rigid.apply(rotations[segments][:, None], translations[segments][:, None], gathered)


def _runs(starts, lengths) -> np.ndarray:
    """starts[k], starts[k] + 1, ... (lengths[k] numbers) for every k, concatenated."""
    lengths = np.asarray(lengths)
    offsets = np.cumsum(lengths) - lengths
    return np.arange(lengths.sum()) + np.repeat(np.asarray(starts) - offsets, lengths)


def _wrap(graph: MotionGraph, frames: np.ndarray) -> np.ndarray:
    """Source frames of `graph` for frames counted on across its loop (as they are, if it has none)."""
    return frames if graph.period is None else frames % graph.period


def _blend_rows(blends, n_frames: int):
    """Over each blend that starts within `n_frames` output frames: the output rows, the source
    frames and segments of the motion blended out of, and the weight of the motion blended into
    (a smoothstep from 0 to 1, exclusive)."""
    out, first, old_segment, blend = blends
    count = np.clip(n_frames - out, 0, blend)
    within = _runs(np.ones_like(count), count)  # 1..count inside each blend
    weight = _smoothstep(within / np.repeat(blend + 1, count))
    return _runs(out, count), _runs(first, count), np.repeat(old_segment, count), weight


def played_positions(graph: MotionGraph, walk: Walk, n_frames: int | None = None) -> np.ndarray:
    """The positions (F, N, D) of the first `n_frames` (default: all) frames `walk` plays through
    `graph`, blends included: what :func:`synthesize_graph` wraps in a Motion."""
    source = graph.motion.positions
    (output_start, source_start, length), rotations, translations, mappings, blends = _plan(graph, walk)
    segment = np.repeat(np.arange(len(length)), length)[:n_frames]
    frames = _wrap(graph, _runs(source_start, length)[:n_frames])
    positions = _place(source, frames, segment, rotations, translations, mappings)
    if len(blends[0]):
        rows, old_frames, old_segments, weight = _blend_rows(blends, len(positions))
        old = _place(source, _wrap(graph, old_frames), old_segments, rotations, translations, mappings)
        weight = weight[:, None, None]
        positions[rows] = (1 - weight) * old + weight * positions[rows]
    return positions


def played_length(graph: MotionGraph, walk: Walk) -> int:
    """How many frames `walk` plays."""
    return int(_plan(graph, walk, placed=False)[0][2].sum())


def blended_frames(graph: MotionGraph, walk: Walk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What each output frame of `walk` plays, blends included: (the source frame blended into
    (F,), the source frame blended out of (F,; the same frame outside blends), the weight of the
    first (F,; 1 outside blends)), for playing other data of the source frames (a skeleton's
    poses) as synthesize plays positions. Raises ValidationError as synthesize does."""
    (_, source_start, length), _, _, _, blends = _plan(graph, walk, placed=False)
    frames = _wrap(graph, _runs(source_start, length))
    previous, weight = frames.copy(), np.ones(len(frames))
    if len(blends[0]):
        rows, old_frames, _, blend_weight = _blend_rows(blends, len(frames))
        previous[rows], weight[rows] = _wrap(graph, old_frames), blend_weight
    return frames, previous, weight


def played_frames(graph: MotionGraph, walk: Walk) -> tuple[np.ndarray, np.ndarray]:
    """What each output frame of `walk` plays: (source frame (F,), the rotation placing it in the
    world (F, D, D)). Over a blend, the motion blended into (the new one). Raises ValidationError
    as synthesize does."""
    (_, source_start, length), rotations, _, _, _ = _plan(graph, walk)
    segment = np.repeat(np.arange(len(length)), length)
    return _wrap(graph, _runs(source_start, length)), rotations[segment]


def synthesize_graph(graph: MotionGraph, walk: Walk) -> Motion:
    """The motion of `walk` through `graph`: one Motion of the graph's agents, at the source dt.

    Raises ValidationError if the walk does not fit the graph (an edge that does not leave the
    node reached, or a transition taken before the previous blend has played out).
    """
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"synthesize needs a flockkit.MotionGraph; got {type(graph).__name__}")
    return Motion._adopt(played_positions(graph, walk), graph.motion.dt)


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
    played = [played_positions(graph, walk) for walk in walks]
    shortest = min(len(p) for p in played)
    if n_frames is None:
        n_frames = shortest
    elif isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or not 1 <= n_frames <= shortest:
        raise ValidationError(f"n_frames must be an integer in 1..{shortest} (the shortest walk); got {n_frames!r}")
    return Motion(positions=np.concatenate([p[:n_frames] for p in played], axis=1), dt=graph.motion.dt)
