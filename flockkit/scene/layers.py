"""Objects split into parts, one motion graph per part (paper 002, section 4).

``GraphLayers`` holds one MotionGraph per part (of a ``Segmentation``) over one source; walking the parts
independently ("asynchronous transitions") and playing them together gives endless, varied motion
of the whole object from a short source. Where parts meet on a mesh, the seams are smoothed (see
:func:`synthesize_layers`). A part whose source is a short cycle (a wing beat, a step) gets a
looping graph with phase shifts from the windowed builder (``MotionGraph.period``,
``MotionGraph.shifts``), so its walks start at any phase and waver in time: duplicates play it
out of step, and no stretch of it repeats exactly.

A mesh whose file holds one point of the surface as several vertices (split where normals or
texture coordinates change, or a triangle soup whose triangles share no vertex) is welded
(``flockkit.mesh.weld_map``): the copies of a point are one point for segmentation and seams, and
play the same position in every frame, so the surface cannot crack; the output keeps every vertex,
in the file's order. :func:`crack_width` measures how far a motion pulls such copies apart.
"""

from __future__ import annotations

import attrs
import numba
import numpy as np
from scipy.sparse import coo_matrix, diags, identity

from .. import _npzfile
from .._arrays import readonly_int
from ..errors import FileFormatError, ValidationError
from ..graphs import MotionGraph, blended_frames, played_length, played_positions, walk_parts
from ..mesh import WELD_TOLERANCE, AnimatedMesh, face_edges, faces_array, object_size, weld_map
from ..motion import Motion
from .features import Features
from .segmentation import Segmentation

__all__ = [
    "GraphLayers",
    "LayeredWalk",
    "walk_layers",
    "synthesize_layers",
    "seam_stretch",
    "crack_width",
    "part_motion",
]

# Files of layers with a looping graph (MotionGraph.period) are version 2, which version 1
# readers would misread; other layers are still written as version 1.
LAYERS_FORMAT_VERSION = 2
PLAIN_LAYERS_FORMAT_VERSION = 1
# Rings of mesh neighbors around a seam whose displacements are smoothed, and the smoothing
# passes (our choice; on the Fox's minute, its copies of each vertex welded, seam edges stretch
# 0.017 on average and 0.52 at most, against 0.019 and 0.47 unsmoothed, and 0.016 and 0.44 with 2
# rings and 8 passes, which cost more time: bench/layers.py).
SEAM_RINGS = 1
SEAM_PASSES = 4
# crack_width measures the copies in blocks of frames whose gaps take about this many bytes, small
# enough to stay in cache.
GATHER_BLOCK_BYTES = 1 << 20


def _faces_or_none(value):
    return None if value is None else faces_array(value, "GraphLayers.faces")


def _welds_or_none(value):
    return None if value is None else readonly_int(value, field="GraphLayers.welds")


@attrs.frozen(kw_only=True, eq=False)
class GraphLayers:
    """One motion graph per part of an object (paper 002's motion graph layer).

    Attributes
    ----------
    source : Motion
        The whole object's motion (a mesh's vertices, a flock's agents).
    segmentation : Segmentation
        The part of each point.
    graphs : tuple of MotionGraph
        Graph k over the motion of part k's points (``segmentation.parts()[k]``, in that order).
    faces : ndarray (F, 3 or 4), optional
        The mesh's faces, when the source is a mesh: synthesis smooths the seams between parts.
    features : flockkit.Features, optional
        The source's feature arrows, one per source frame (paper 002, section 4.2).
    welds : ndarray of int (N,), optional
        The point each point is welded to (``flockkit.mesh.weld_map``): the smallest index of the
        copies of one surface point, which share a part; seams are smoothed over the welded
        faces and every copy plays its first's position, so copies never part. None: no point
        is welded to another.
    """

    source: Motion
    segmentation: Segmentation
    graphs: tuple = attrs.field(converter=tuple)
    faces: np.ndarray | None = attrs.field(default=None, converter=_faces_or_none)
    features: Features | None = attrs.field(default=None)
    welds: np.ndarray | None = attrs.field(default=None, converter=_welds_or_none)
    _playback: object = attrs.field(init=False, default=None, repr=False, eq=False)  # made by synthesis

    def __attrs_post_init__(self):
        if self.features is not None and (
            not isinstance(self.features, Features)
            or self.features.n_frames != self.source.n_frames
            or self.features.vectors.shape[1] not in (2, 3)
        ):
            raise ValidationError(
                f"GraphLayers.features must be flockkit.Features with one arrow per source frame "
                f"({self.source.n_frames})"
            )
        self.segmentation.check_fits(self.source, "the layers' source")
        if len(self.graphs) != self.segmentation.n_parts:
            raise ValidationError(
                f"GraphLayers has {len(self.graphs)} graphs for {self.segmentation.n_parts} parts; it needs one a part"
            )
        for k, (graph, points) in enumerate(zip(self.graphs, self.segmentation.parts())):
            if not isinstance(graph, MotionGraph) or graph.motion.n_agents != len(points):
                raise ValidationError(
                    f"GraphLayers.graphs[{k}] must be a MotionGraph over part {k}'s {len(points)} points"
                )
        if self.faces is not None and len(self.faces) and self.faces.max() >= self.source.n_agents:
            raise ValidationError(f"GraphLayers.faces index points beyond the source's {self.source.n_agents}")
        if self.welds is not None:
            check_welds(self.welds, self.segmentation.labels, "GraphLayers.welds")

    @property
    def n_parts(self) -> int:
        return self.segmentation.n_parts

    def stats(self) -> dict:
        return {
            "parts": self.n_parts,
            "points": self.source.n_agents,
            "points_per_part": [len(p) for p in self.segmentation.parts()],
            "graphs": [graph.stats() for graph in self.graphs],
        }

    def __eq__(self, other):
        if not isinstance(other, GraphLayers):
            return NotImplemented
        faces_equal = (self.faces is None and other.faces is None) or (
            self.faces is not None and other.faces is not None and np.array_equal(self.faces, other.faces)
        )
        return (
            self.source == other.source and self.segmentation == other.segmentation and self.graphs == other.graphs
            and faces_equal and self.features == other.features and _same_welds(self.welds, other.welds)
        )  # fmt: skip

    __hash__ = None

    def _payload(self) -> tuple[dict, dict]:
        """(arrays, metadata) of the source, the segmentation, the faces, the features and every
        part's graph, as save writes them."""
        from ..graphs.graph import _thaw

        arrays = {**self.source._to_arrays(), "labels": self.segmentation.labels}
        if self.faces is not None:
            arrays["faces"] = self.faces
        if self.features is not None:
            arrays["features"] = self.features.vectors
        if self.welds is not None:
            arrays["welds"] = self.welds
        for k, graph in enumerate(self.graphs):
            arrays.update({f"part{k}.{name}": array for name, array in graph._to_arrays().items()})
        metadata = {
            "dt": self.source.dt,
            "n_parts": self.n_parts,
            "params": [_thaw(g.params) for g in self.graphs],
            "provenance": [_thaw(g.provenance) for g in self.graphs],
        }
        if self.features is not None and self.features.speed is not None:
            metadata["feature_speed"] = self.features.speed
        return arrays, metadata

    @classmethod
    def _from_payload(cls, arrays, header, source) -> GraphLayers:
        """The inverse of :meth:`_payload`; FileFormatError naming `source`."""
        try:
            motion = Motion._from_arrays(arrays, header["dt"])
            segmentation = Segmentation(labels=arrays["labels"], n_parts=header["n_parts"])
            graphs = []
            for k, points in enumerate(segmentation.parts()):
                own = {name.split(".", 1)[1]: a for name, a in arrays.items() if name.startswith(f"part{k}.")}
                graphs.append(MotionGraph._from_arrays(own, part_motion(motion, points), header["params"][k],
                                                       header["provenance"][k], source))  # fmt: skip
            features = None
            if "features" in arrays:
                features = Features(vectors=arrays["features"], dt=motion.dt, speed=header.get("feature_speed"))
            return cls(source=motion, segmentation=segmentation, graphs=graphs, faces=arrays.get("faces"),
                       features=features, welds=arrays.get("welds"))  # fmt: skip
        except (KeyError, IndexError, TypeError, ValidationError) as exc:
            raise FileFormatError(f"{source}: invalid motion graph layers: {type(exc).__name__}: {exc}") from None

    def save(self, path) -> None:
        """Write the source, the segmentation, the faces and every part's graph to one .npz (atomic)."""
        arrays, metadata = self._payload()
        looping = any(graph.loops for graph in self.graphs)
        version = LAYERS_FORMAT_VERSION if looping else PLAIN_LAYERS_FORMAT_VERSION
        _npzfile.write(path, kind="layers", version=version, arrays=arrays, metadata=metadata)

    @classmethod
    def load(cls, path) -> GraphLayers:
        """Read a file written by :meth:`save`; FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(
            path, kind="layers", versions=(PLAIN_LAYERS_FORMAT_VERSION, LAYERS_FORMAT_VERSION)
        )
        return cls._from_payload(arrays, header, path)


def _same_welds(a, b) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def check_welds(welds: np.ndarray, labels: np.ndarray, field: str) -> None:
    """ValidationError naming `field` unless `welds` is a weld map over `labels`' points (one entry
    a point, each the smallest of its group: welds[welds] == welds <= its index) whose groups lie
    in one part each."""
    n = len(labels)
    if welds.shape != (n,):
        raise ValidationError(f"{field} must have one entry per point ({n}); got shape {welds.shape}")
    if n and (welds.min() < 0 or np.any(welds > np.arange(n)) or np.any(welds[welds] != welds)):
        raise ValidationError(
            f"{field} must map each point to the smallest point of its group (0 <= welds[i] <= i, "
            f"welds[welds] == welds), as flockkit.mesh.weld_map gives"
        )
    split = np.flatnonzero(labels[welds] != labels)
    if len(split):
        v = int(split[0])
        raise ValidationError(
            f"{field}: point {v} is welded to point {int(welds[v])} (they coincide throughout the source) but the "
            f"segmentation puts them in parts {int(labels[v])} and {int(labels[welds[v]])}; welded points must "
            f"share a part (segment with the same welding, or pass weld=False)"
        )


@attrs.frozen(kw_only=True, eq=False)
class LayeredWalk:
    """One walk per part of a GraphLayers, in part order."""

    walks: tuple = attrs.field(converter=tuple)

    def __eq__(self, other):
        if not isinstance(other, LayeredWalk):
            return NotImplemented
        return self.walks == other.walks

    __hash__ = None


def part_motion(source: Motion, points: np.ndarray) -> Motion:
    """The motion of `points` of `source`, in that order."""
    return Motion(positions=source.positions[:, points], dt=source.dt)


def walk_layers(layers: GraphLayers, *, strategy="random", duration: float | None = None, seed: int | None = None,
                **params) -> LayeredWalk:  # fmt: skip
    """Every part walked on its own, each with its own stream of random numbers from `seed`
    (``flockkit.graphs.walk_parts``), for `duration` seconds (default: the source's length)."""
    duration = layers.source.duration if duration is None else duration
    return LayeredWalk(walks=walk_parts(layers.graphs, strategy=strategy, duration=duration, seed=seed, **params))


def synthesize_layers(layers: GraphLayers, walk: LayeredWalk) -> Motion:
    """The whole object played from its parts' walks, cut to the shortest: every part continuous
    across its own transitions (blended as synthesize does). On a mesh, the seams are smoothed:
    within SEAM_RINGS rings of mesh neighbors of a face that spans two parts, each point's
    displacement from its mean position in the source is replaced, SEAM_PASSES times, by the mean
    of its neighbors' (points farther away keep theirs), so a seam bends over a few edges instead of
    tearing. Where the layers weld points (``GraphLayers.welds``), the faces are read with every
    point replaced by the one it is welded to, so the copies of a point are one point with all
    their neighbours, and every copy plays that point's position: the output has every source
    point, in the source's order, and welded points never part.

    One compiled pass writes every frame once: each point reads its part's source frame, or
    blends two of them where the part's walk blends (``flockkit.graphs.blended_frames``), or reads
    the part's placed frames where its walk moves it. The smoothing is linear, so each part's
    share of it is made once per source frame and played the same way, summed per frame."""
    return Motion._adopt(played_layers(layers, walk), layers.source.dt)


def played_layers(layers: GraphLayers, walk: LayeredWalk, n_frames: int | None = None, matrix=None,
                  offset=None) -> np.ndarray:  # fmt: skip
    """The positions (F, N, D) :func:`synthesize_layers` plays, only the first `n_frames` (default:
    all; frames past them are never made), each point p written as ``matrix @ p + offset`` where
    `matrix` (D, D) and `offset` (D,) are given: an object placed in the world (scaled, turned and
    moved) by the same pass that plays it, with no second pass over the frames."""
    if not isinstance(walk, LayeredWalk) or len(walk.walks) != layers.n_parts:
        raise ValidationError(f"synthesizing {layers.n_parts} layers needs a LayeredWalk of {layers.n_parts} walks")
    pairs = list(zip(layers.graphs, walk.walks))
    in_place = [_stays_in_place(graph, w) for graph, w in pairs]
    blends = [blended_frames(graph, w) if still else None for (graph, w), still in zip(pairs, in_place)]
    frames = min(len(b[0]) if b is not None else played_length(graph, w) for (graph, w), b in zip(pairs, blends))
    if n_frames is not None:
        frames = min(frames, int(n_frames))
    mapped = matrix is not None
    d = layers.source.dims
    matrix = np.ascontiguousarray(matrix if mapped else np.eye(d), dtype=np.float64)
    offset = np.ascontiguousarray(offset if mapped else np.zeros(d), dtype=np.float64)
    playback = _playback(layers)
    k_parts = layers.n_parts
    # per frame and part: the first item of the frame blended into (or played), of the frame
    # blended out of, and the weight of the first; the same for the part's share of the seams
    new_row, old_row = np.empty((frames, k_parts), dtype=np.int64), np.empty((frames, k_parts), dtype=np.int64)
    share_new, share_old = np.zeros((frames, k_parts), dtype=np.int64), np.zeros((frames, k_parts), dtype=np.int64)
    weight = np.ones((frames, k_parts))
    part_moving, share_moving = np.zeros(k_parts, dtype=np.bool_), np.zeros(k_parts, dtype=np.bool_)
    moving, moved_rows = [], 0
    for k, ((graph, w), blend) in enumerate(zip(pairs, blends)):
        n_k, share = graph.motion.n_agents, playback.shares[k]
        if blend is not None:
            new, old, weight[:, k] = (a[:frames] for a in blend)
            new_row[:, k], old_row[:, k] = playback.base[k] + new * n_k, playback.base[k] + old * n_k
            if share is not None:
                share_new[:, k], share_old[:, k] = share.base + new * share.width, share.base + old * share.width
            continue
        # the part's walk moves it: its placed frames (and their share of the seams) are its items
        placed = played_positions(graph, w, frames)
        part_moving[k] = True
        new_row[:, k] = old_row[:, k] = moved_rows + np.arange(frames) * n_k
        moving.append(placed.reshape(-1, d))
        moved_rows += placed.shape[0] * n_k
        if share is not None:
            share_moving[k] = True
            share_new[:, k] = share_old[:, k] = moved_rows + np.arange(frames) * share.width
            moving.append(_apply(share.operator, placed[:, share.columns]).reshape(-1, d))
            moved_rows += frames * share.width
    moving = np.concatenate(moving) if moving else np.empty((0, d))
    positions = np.empty((frames, layers.source.n_agents, d))
    _play(playback.items, moving, part_moving, new_row, old_row, weight, share_moving, share_new, share_old,
          playback.runs, playback.offset, playback.points, playback.local, playback.first, mapped, matrix, offset,
          positions)  # fmt: skip
    return positions


@numba.njit(cache=True, nogil=True)
def _play(items, moving, part_moving, new_row, old_row, weight, share_moving, share_new, share_old, runs, offset,
          points, local, first, mapped, matrix, shift, out):  # fmt: skip
    """Write every frame of `out` (T, N, D): part k's points (``points[first[k]:first[k + 1]]``)
    read their items, row ``new_row[t, k] + local`` of `items` (of `moving` where
    ``part_moving[k]``), blended as ``(1 - w) * old + w * new`` with the row from ``old_row``
    where the part's weight w is below 1; the smoothed points (the last group) read `offset` plus
    every part's share, summed in `runs` (part, first, stop, first row of the share) order. Where
    `mapped`, each frame is then mapped to ``matrix @ p + shift`` while it is still in cache.

    It works on flat views and spells out D = 3 (a mesh's case): a loop over the coordinates
    there ran at half the speed. It runs on one thread: it moves the output's bytes about as fast
    as filling it does, and a second thread gave nothing on 2 cores."""
    n, dims = out.shape[1], out.shape[2]
    flat, items, moving = out.reshape(-1), items.reshape(-1), moving.reshape(-1)
    smoothed = np.empty(offset.size)
    for t in range(weight.shape[0]):
        _play_frame(items, moving, part_moving, new_row, old_row, weight, share_moving, share_new, share_old, runs,
                    offset, points, local, first, flat, smoothed, t, n, dims)  # fmt: skip
        if mapped:
            affine(flat, t * n * dims, (t + 1) * n * dims, dims, matrix, shift)


@numba.njit(cache=True, nogil=True)
def affine(flat, start, stop, dims, matrix, shift):
    """Map the points of ``flat[start:stop]`` (D coordinates each) to ``matrix @ p + shift``, in
    place."""
    if dims == 3:
        m00, m01, m02 = matrix[0, 0], matrix[0, 1], matrix[0, 2]
        m10, m11, m12 = matrix[1, 0], matrix[1, 1], matrix[1, 2]
        m20, m21, m22 = matrix[2, 0], matrix[2, 1], matrix[2, 2]
        for o in range(start, stop, 3):
            x, y, z = flat[o], flat[o + 1], flat[o + 2]
            flat[o] = m00 * x + m01 * y + m02 * z + shift[0]
            flat[o + 1] = m10 * x + m11 * y + m12 * z + shift[1]
            flat[o + 2] = m20 * x + m21 * y + m22 * z + shift[2]
    else:
        for o in range(start, stop, 2):
            x, y = flat[o], flat[o + 1]
            flat[o] = matrix[0, 0] * x + matrix[0, 1] * y + shift[0]
            flat[o + 1] = matrix[1, 0] * x + matrix[1, 1] * y + shift[1]


@numba.njit(cache=True, nogil=True)
def _play_frame(items, moving, part_moving, new_row, old_row, weight, share_moving, share_new, share_old, runs,
                offset, points, local, first, flat, smoothed, t, n, dims):  # fmt: skip
    """Frame t of :func:`_play` into `flat` (the output's flat view), the smoothed points summed in
    `smoothed`."""
    n_parts = weight.shape[1]
    if len(runs):
        smoothed[:] = offset.reshape(-1)
        for r in range(len(runs)):
            k = runs[r, 0]
            source = moving if share_moving[k] else items
            w = weight[t, k]
            a, size = runs[r, 1] * dims, (runs[r, 2] - runs[r, 1]) * dims
            into = (share_new[t, k] + runs[r, 3]) * dims
            if w == 1.0:
                for j in range(size):
                    smoothed[a + j] += source[into + j]
            else:
                out_of = (share_old[t, k] + runs[r, 3]) * dims
                for j in range(size):
                    smoothed[a + j] += (1 - w) * source[out_of + j] + w * source[into + j]
    frame = t * n * dims
    for k in range(n_parts):
        source = moving if part_moving[k] else items
        w = weight[t, k]
        into, out_of = new_row[t, k] * dims, old_row[t, k] * dims
        if dims == 3 and w == 1.0:
            for p in range(first[k], first[k + 1]):
                o, s = frame + points[p] * 3, into + local[p] * 3
                flat[o], flat[o + 1], flat[o + 2] = source[s], source[s + 1], source[s + 2]
        elif dims == 3:
            for p in range(first[k], first[k + 1]):
                o, s, q = frame + points[p] * 3, into + local[p] * 3, out_of + local[p] * 3
                flat[o] = (1 - w) * source[q] + w * source[s]
                flat[o + 1] = (1 - w) * source[q + 1] + w * source[s + 1]
                flat[o + 2] = (1 - w) * source[q + 2] + w * source[s + 2]
        else:
            for p in range(first[k], first[k + 1]):
                o, s, q = frame + points[p] * dims, into + local[p] * dims, out_of + local[p] * dims
                for c in range(dims):
                    flat[o + c] = source[s + c] if w == 1.0 else (1 - w) * source[q + c] + w * source[s + c]
    for p in range(first[n_parts], first[n_parts + 1]):
        o, s = frame + points[p] * dims, local[p] * dims
        for c in range(dims):
            flat[o + c] = smoothed[s + c]


def _stays_in_place(graph, walk) -> bool:
    """Whether `walk` plays every frame where the source has it (no placement, no exchange of
    points), as the windowed builder's graphs do."""
    d, n = graph.motion.dims, graph.motion.n_agents
    rotation, translation = walk.pose(d)
    tables = graph.tables
    return (
        np.array_equal(rotation, np.eye(d)) and not np.any(translation) and not np.any(tables.translation)
        and np.array_equal(tables.rotation, np.broadcast_to(np.eye(d), tables.rotation.shape))
        and np.array_equal(tables.assignment, np.broadcast_to(np.arange(n), tables.assignment.shape))
    )  # fmt: skip


def _local_index(segmentation: Segmentation) -> np.ndarray:
    """Each point's index within its part."""
    local = np.empty(len(segmentation.labels), dtype=np.int64)
    for points in segmentation.parts():
        local[points] = np.arange(len(points))
    return local


def _adjacency(n_points: int, faces: np.ndarray):
    edges = face_edges(faces)
    rows, cols = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
    return coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_points, n_points)).tocsr()


def welded_faces(layers: GraphLayers) -> np.ndarray:
    """The layers' faces with every point replaced by the one it is welded to."""
    return layers.faces if layers.welds is None else layers.welds[layers.faces]


def seam_points(layers: GraphLayers) -> np.ndarray:
    """Points of faces that span two or more parts (of the welded faces)."""
    faces = welded_faces(layers)
    labels = layers.segmentation.labels[faces]
    spanning = np.any(labels != labels[:, :1], axis=1)
    return np.unique(faces[spanning])


@attrs.frozen(eq=False)
class _Share:
    """One part's share of the seam smoothing: `operator` (sparse, `width` rows) applied to the
    part's points `columns`; its rows at source frame f are items ``base + f * width`` on."""

    columns: np.ndarray
    operator: object
    base: int
    width: int


@attrs.frozen(eq=False)
class _Playback:
    """What synthesis of some layers reads whatever the walk (made once per layers, SEAM_RINGS and
    SEAM_PASSES): `items`, every part's source frames (part k's frame f from row ``base[k] + f *
    n_k``) followed by every part's share of the smoothing at each of them; `shares`, a _Share
    per part (None for a part that gives none); `runs` (part, first, stop, first row of the share)
    adding the shares to the smoothed points, whose positions are `offset` plus those sums; and
    the points grouped by what they read: ``points[first[k]:first[k + 1]]`` read part k's items
    at their `local` index, the last group the smoothed points at theirs."""

    key: tuple
    items: np.ndarray
    base: np.ndarray
    shares: list
    runs: np.ndarray
    offset: np.ndarray
    points: np.ndarray
    local: np.ndarray
    first: np.ndarray


def _playback(layers: GraphLayers) -> _Playback:
    key = (SEAM_RINGS, SEAM_PASSES)
    if layers._playback is not None and layers._playback.key == key:
        return layers._playback
    k_parts, d = layers.n_parts, layers.source.dims
    items = [graph.motion.positions.reshape(-1, d) for graph in layers.graphs]
    base = np.cumsum([0] + [len(block) for block in items])
    column, local = layers.segmentation.labels.astype(np.int64), _local_index(layers.segmentation)
    shares, runs, offset = [None] * k_parts, np.zeros((0, 4), dtype=np.int64), np.zeros((0, d))
    seams = _seams(layers)
    if seams is not None:
        smoothed, offset, operators = seams
        column[smoothed], local[smoothed] = k_parts, np.arange(len(smoothed))
        rows, runs = int(base[-1]), []
        for k, (graph, found) in enumerate(zip(layers.graphs, operators)):
            if found is None:
                continue
            columns, own_runs, operator = found
            shares[k] = _Share(columns=columns, operator=operator, base=rows, width=operator.shape[0])
            items.append(_apply(operator, graph.motion.positions[:, columns]).reshape(-1, d))
            rows += len(items[-1])
            runs += [(k, a, b, row) for a, b, row in own_runs]
        runs = np.array(runs, dtype=np.int64).reshape(-1, 4)
    if layers.welds is not None:  # every copy reads what the point it is welded to reads
        column, local = column[layers.welds], local[layers.welds]
    points = np.argsort(column, kind="stable")
    first = np.searchsorted(column[points], np.arange(k_parts + 2))
    playback = _Playback(key=key, items=np.concatenate(items), base=base[:-1], shares=shares, runs=runs,
                         offset=np.ascontiguousarray(offset, dtype=np.float64), points=points, local=local[points],
                         first=first)  # fmt: skip
    object.__setattr__(layers, "_playback", playback)
    return playback


def _seams(layers: GraphLayers):
    """The seam smoothing of `layers`, None where there is none: (the smoothed points, the
    offset of their positions, and per part (None for a part that gives no share) the part's
    points that its share reads, runs (first, stop, first row of the share) of smoothed points
    that share adds to, and the share's operator). The smoothed points are ordered by the parts
    that give them a share, so each part's rows are a few runs."""
    if layers.faces is None or layers.n_parts < 2 or SEAM_PASSES < 1:
        return None
    adjacency = _adjacency(layers.source.n_agents, welded_faces(layers))
    zone = np.zeros(layers.source.n_agents, dtype=bool)
    zone[seam_points(layers)] = True
    for _ in range(SEAM_RINGS):
        zone |= (adjacency @ zone.astype(float)) > 0
    # the passes read the zone and its neighbors only: work on that block of points
    involved = np.flatnonzero(zone | ((adjacency @ zone.astype(float)) > 0))
    inner = zone[involved]
    degree = np.asarray(adjacency.sum(axis=1)).ravel()[involved]
    mean_of_neighbors = adjacency[involved][:, involved].multiply(1.0 / np.maximum(degree, 1)[:, None])
    # one pass: inner rows take their neighbors' mean displacement, the others keep theirs; the
    # passes composed: smoothed positions = composed @ involved positions + offset
    one_pass = (diags(inner.astype(float)) @ mean_of_neighbors + diags((~inner).astype(float))).tocsr()
    composed = identity(len(involved), format="csr")
    for _ in range(SEAM_PASSES):
        composed = one_pass @ composed
    composed = composed[np.flatnonzero(inner)].tocsc()
    labels, local = layers.segmentation.labels[involved], _local_index(layers.segmentation)[involved]
    mine = [np.flatnonzero(labels == k) for k in range(layers.n_parts)]
    order = np.lexsort([composed[:, columns].getnnz(axis=1) > 0 for columns in mine])
    composed = composed[order]
    operators = []
    for columns in mine:
        operator = composed[:, columns].tocsr()
        touched = np.flatnonzero(operator.getnnz(axis=1))
        if not len(touched):
            operators.append(None)
            continue
        breaks = np.flatnonzero(np.diff(touched) != 1) + 1
        firsts, lasts = np.append(0, breaks), np.append(breaks, len(touched)) - 1
        runs = [(touched[a], touched[b] + 1, a) for a, b in zip(firsts.tolist(), lasts.tolist())]
        operators.append((local[columns], runs, operator[touched]))
    rest = layers.source.positions.mean(axis=0)[involved]
    return involved[inner][order], rest[inner][order] - composed @ rest, operators


def _apply(operator, positions: np.ndarray) -> np.ndarray:
    """operator (K, M) applied to every frame of positions (T, M, D): (T, K, D)."""
    frames, m, d = positions.shape
    flat = np.ascontiguousarray(positions.transpose(1, 0, 2)).reshape(m, frames * d)
    return np.ascontiguousarray((operator @ flat).reshape(-1, frames, d).transpose(1, 0, 2))


def seam_stretch(motion: Motion, faces, labels=None, *, reference: Motion | None = None) -> float:
    """The largest relative change of an edge's length, |length / rest - 1|, where rest is the
    edge's mean length in `reference` (default: `motion` itself), over the edges of faces that
    span two parts of `labels` (default: every edge)."""
    faces = np.asarray(faces)
    if labels is not None:
        labels = np.asarray(labels)[faces]
        faces = faces[np.any(labels != labels[:, :1], axis=1)]
    if not len(faces):
        return 0.0
    edges = face_edges(faces)

    def length(positions):
        return np.linalg.norm(positions[:, edges[:, 0]] - positions[:, edges[:, 1]], axis=2)

    lengths = length(motion.positions)
    mean = length((reference or motion).positions).mean(axis=0)
    return float(np.max(np.abs(lengths / np.maximum(mean, 1e-300) - 1)))


def crack_width(motion, reference, *, tolerance: float = WELD_TOLERANCE, statistic: str = "max") -> float:
    """How far `motion` pulls apart the copies of one surface point: points of `reference` (a
    Motion, an AnimatedMesh, or GraphLayers, whose source is read) that stay within `tolerance`
    times its size of each other in every frame (``flockkit.mesh.weld_map``), measured in
    `motion` (a Motion or an AnimatedMesh over the same points, e.g. what synthesis played).

    Returns the largest (`statistic` "max") or mean ("mean") distance, over frames and over every
    copy, between a copy and the first point of its group, relative to
    ``flockkit.mesh.object_size(reference)``; 0.0 where `reference` has no copies. A visible crack
    in the surface is a large value; seam_stretch cannot see one, since the copies share no edge."""
    if isinstance(reference, GraphLayers):
        reference = reference.source
    if statistic not in ("max", "mean"):
        raise ValidationError(f"crack_width: statistic must be 'max' or 'mean'; got {statistic!r}")
    if isinstance(motion, AnimatedMesh):
        motion = motion.motion
    if not isinstance(motion, Motion):
        raise ValidationError(
            f"crack_width: motion must be a flockkit.Motion or AnimatedMesh; got {type(motion).__name__}"
        )
    if not isinstance(reference, Motion | AnimatedMesh):
        raise ValidationError(
            f"crack_width: reference must be a flockkit.Motion, AnimatedMesh or GraphLayers; got "
            f"{type(reference).__name__}"
        )
    welds = weld_map(reference, tolerance)
    n = len(welds)
    if motion.n_agents != n:
        raise ValidationError(f"crack_width: motion has {motion.n_agents} points but the reference has {n}")
    copies = np.flatnonzero(welds != np.arange(n))
    size = object_size(reference)
    if not len(copies) or size == 0:
        return 0.0
    largest, total = 0.0, 0.0
    step = max(1, GATHER_BLOCK_BYTES // (24 * len(copies)))
    for first in range(0, motion.n_frames, step):
        block = motion.positions[first : first + step]
        gaps = np.linalg.norm(block[:, copies] - block[:, welds[copies]], axis=2)
        largest, total = max(largest, float(gaps.max())), total + float(gaps.sum())
    return (largest if statistic == "max" else total / (motion.n_frames * len(copies))) / size
