"""Objects split into parts, one motion graph per part (paper 002, section 4).

A ``Segmentation`` labels each point of a motion (a mesh's vertices, a flock's agents) with its
part. ``GraphLayers`` holds one MotionGraph per part over one source; walking the parts
independently ("asynchronous transitions") and playing them together gives endless, varied motion
of the whole object from a short source. Where parts meet on a mesh, the seams are smoothed (see
:func:`synthesize_layers`).
"""

from __future__ import annotations

import attrs
import numpy as np
from scipy.sparse import coo_matrix, diags, identity

from . import _npzfile
from ._arrays import readonly_int
from .errors import FileFormatError, ValidationError
from .features import Features
from .mesh import AnimatedMesh, face_edges, faces_array
from .motion import Motion

__all__ = ["Segmentation", "GraphLayers", "LayeredWalk", "seam_stretch"]

SEGMENTATION_FORMAT_VERSION = 1
LAYERS_FORMAT_VERSION = 1
# Rings of mesh neighbors around a seam whose displacements are smoothed, and the smoothing
# passes (our choice, measured on the Fox's minute: seams stretch 0.042 at most, against 0.48
# unsmoothed and 0.039 with 2 rings and 8 passes, which cost 30% more time).
SEAM_RINGS = 1
SEAM_PASSES = 4
# Synthesis copies a part's points run by run when its runs of consecutive indices hold this many
# points on average, and gathers them otherwise.
MIN_RUN = 4
# Seam smoothing works on blocks of frames of about this many bytes, small enough to stay in cache.
SEAM_BLOCK_BYTES = 1 << 20


def _labels(value) -> np.ndarray:
    array = readonly_int(value, field="Segmentation.labels")
    if array.ndim != 1 or len(array) == 0:
        raise ValidationError(f"Segmentation.labels must be a non-empty 1D array; got shape {array.shape}")
    return array


@attrs.frozen(kw_only=True, eq=False)
class Segmentation:
    """The part of each point: `labels` (N,) in 0..n_parts-1, every part non-empty."""

    labels: np.ndarray = attrs.field(converter=_labels)
    n_parts: int = attrs.field()

    def __attrs_post_init__(self):
        if isinstance(self.n_parts, bool) or not isinstance(self.n_parts, int | np.integer) or self.n_parts < 1:
            raise ValidationError(f"Segmentation.n_parts must be a positive integer; got {self.n_parts!r}")
        if self.labels.min() < 0 or self.labels.max() >= self.n_parts:
            raise ValidationError(
                f"Segmentation.labels must lie in 0..{self.n_parts - 1}; got {self.labels.min()}..{self.labels.max()}"
            )
        empty = np.flatnonzero(np.bincount(self.labels, minlength=self.n_parts) == 0)
        if len(empty):
            raise ValidationError(f"Segmentation: part {int(empty[0])} of {self.n_parts} has no point")

    @property
    def n_points(self) -> int:
        return len(self.labels)

    def parts(self) -> list[np.ndarray]:
        """Each part's point indices, increasing."""
        order = np.argsort(self.labels, kind="stable")
        return np.split(order, np.cumsum(np.bincount(self.labels, minlength=self.n_parts))[:-1])

    def check_fits(self, motion: Motion, what: str = "the motion") -> None:
        """ValidationError unless there is one label per point of `motion`."""
        if self.n_points != motion.n_agents:
            raise ValidationError(f"the segmentation labels {self.n_points} points but {what} has {motion.n_agents}")

    def __eq__(self, other):
        if not isinstance(other, Segmentation):
            return NotImplemented
        return self.n_parts == other.n_parts and np.array_equal(self.labels, other.labels)

    __hash__ = None

    def save(self, path) -> None:
        """Write to one .npz with JSON metadata (atomic)."""
        _npzfile.write(path, kind="segmentation", version=SEGMENTATION_FORMAT_VERSION, arrays={"labels": self.labels},
                       metadata={"n_parts": self.n_parts})  # fmt: skip

    @classmethod
    def load(cls, path) -> Segmentation:
        arrays, header = _npzfile.read(path, kind="segmentation", versions=(SEGMENTATION_FORMAT_VERSION,))
        try:
            return cls(labels=arrays["labels"], n_parts=header["n_parts"])
        except (KeyError, ValidationError) as exc:
            raise FileFormatError(f"{path}: invalid segmentation: {type(exc).__name__}: {exc}") from None


def motion_of(source, what: str = "source") -> Motion:
    """The Motion of a Motion or an AnimatedMesh."""
    if isinstance(source, AnimatedMesh):
        return source.motion
    if isinstance(source, Motion):
        return source
    raise ValidationError(f"{what} must be a flockkit.Motion or flockkit.AnimatedMesh; got {type(source).__name__}")


def canonical_labels(labels) -> np.ndarray:
    """Part labels renamed 0, 1, ... in order of each part's first point: equal partitions give
    equal arrays, whatever the names a segmenter chose."""
    _, first, inverse = np.unique(np.asarray(labels), return_index=True, return_inverse=True)
    return np.argsort(np.argsort(first))[inverse]


def same_partition(a, b) -> bool:
    """Whether two labelings split the points the same way, whatever the part names."""
    return np.array_equal(canonical_labels(a), canonical_labels(b))


def _faces_or_none(value):
    return None if value is None else faces_array(value, "GraphLayers.faces")


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
    """

    source: Motion
    segmentation: Segmentation
    graphs: tuple = attrs.field(converter=tuple)
    faces: np.ndarray | None = attrs.field(default=None, converter=_faces_or_none)
    features: Features | None = attrs.field(default=None)
    _seams: tuple | None = attrs.field(init=False, default=None, repr=False, eq=False)  # made by synthesis
    _runs: list | None = attrs.field(init=False, default=None, repr=False, eq=False)  # made by synthesis

    def __attrs_post_init__(self):
        from .graph import MotionGraph

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
            and faces_equal and self.features == other.features
        )  # fmt: skip

    __hash__ = None

    def _payload(self) -> tuple[dict, dict]:
        """(arrays, metadata) of the source, the segmentation, the faces, the features and every
        part's graph, as save writes them."""
        from .graph import _thaw

        arrays = {**self.source._to_arrays(), "labels": self.segmentation.labels}
        if self.faces is not None:
            arrays["faces"] = self.faces
        if self.features is not None:
            arrays["features"] = self.features.vectors
        for k, graph in enumerate(self.graphs):
            arrays.update({f"part{k}.{name}": array for name, array in graph._to_arrays().items()})
        metadata = {
            "dt": self.source.dt,
            "n_parts": self.n_parts,
            "params": [_thaw(g.params) for g in self.graphs],
            "provenance": [_thaw(g.provenance) for g in self.graphs],
        }
        return arrays, metadata

    @classmethod
    def _from_payload(cls, arrays, header, source) -> GraphLayers:
        """The inverse of :meth:`_payload`; FileFormatError naming `source`."""
        from .graph import MotionGraph

        try:
            motion = Motion._from_arrays(arrays, header["dt"])
            segmentation = Segmentation(labels=arrays["labels"], n_parts=header["n_parts"])
            graphs = []
            for k, points in enumerate(segmentation.parts()):
                own = {name.split(".", 1)[1]: a for name, a in arrays.items() if name.startswith(f"part{k}.")}
                graphs.append(MotionGraph._from_arrays(own, part_motion(motion, points), header["params"][k],
                                                       header["provenance"][k], source))  # fmt: skip
            features = Features(vectors=arrays["features"], dt=motion.dt) if "features" in arrays else None
            return cls(source=motion, segmentation=segmentation, graphs=graphs, faces=arrays.get("faces"),
                       features=features)  # fmt: skip
        except (KeyError, IndexError, TypeError, ValidationError) as exc:
            raise FileFormatError(f"{source}: invalid motion graph layers: {type(exc).__name__}: {exc}") from None

    def save(self, path) -> None:
        """Write the source, the segmentation, the faces and every part's graph to one .npz (atomic)."""
        arrays, metadata = self._payload()
        _npzfile.write(path, kind="layers", version=LAYERS_FORMAT_VERSION, arrays=arrays, metadata=metadata)

    @classmethod
    def load(cls, path) -> GraphLayers:
        """Read a file written by :meth:`save`; FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(path, kind="layers", versions=(LAYERS_FORMAT_VERSION,))
        return cls._from_payload(arrays, header, path)


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


def walk_layers(layers: GraphLayers, *, strategy, duration, seed, params) -> LayeredWalk:
    """Every part walked on its own, each with its own stream of random numbers from `seed`."""
    from .convenience import walk

    streams = np.random.SeedSequence(seed).spawn(layers.n_parts)
    return LayeredWalk(
        walks=[
            walk(graph, strategy=strategy, duration=duration, seed=int(stream.generate_state(1)[0]), **params)
            for graph, stream in zip(layers.graphs, streams)
        ]
    )


def synthesize_layers(layers: GraphLayers, walk: LayeredWalk) -> Motion:
    """The whole object played from its parts' walks, cut to the shortest: every part continuous
    across its own transitions (blended as synthesize does). On a mesh, the seams are smoothed:
    within SEAM_RINGS rings of mesh neighbors of a face that spans two parts, each point's
    displacement from its mean position in the source is replaced, SEAM_PASSES times, by the mean
    of its neighbors' (points farther away keep theirs), so a seam bends over a few edges instead of
    tearing."""
    from .synthesis import _positions

    if not isinstance(walk, LayeredWalk) or len(walk.walks) != layers.n_parts:
        raise ValidationError(f"synthesizing {layers.n_parts} layers needs a LayeredWalk of {layers.n_parts} walks")
    played = [_positions(graph, w) for graph, w in zip(layers.graphs, walk.walks)]  # no Motion each: no copies
    frames = min(len(p) for p in played)
    positions = np.empty((frames, layers.source.n_agents, layers.source.dims))
    for part, (points, shift, runs) in zip(played, _part_runs(layers)):
        if runs is None:  # scattered points: one gather
            positions[:, points] = part[:frames]
            continue
        for start, stop in runs:  # runs of consecutive points: slices copy far faster than a gather
            positions[:, start:stop] = part[:frames, start - shift[start] : stop - shift[start]]
    if layers.faces is not None and layers.n_parts > 1 and SEAM_PASSES > 0:
        positions = _smooth_seams(positions, layers)
    return Motion._adopt(positions, layers.source.dt)


def _part_runs(layers: GraphLayers):
    """Per part: its points and, where they form runs of MIN_RUN consecutive indices on average,
    each point's index minus its index in the part and the (start, stop) of each run; made once
    per layers."""
    if layers._runs is None:
        found = []
        for points in layers.segmentation.parts():
            breaks = np.flatnonzero(np.diff(points) != 1) + 1
            if len(breaks) + 1 > max(1, len(points) // MIN_RUN):
                found.append((points, None, None))
                continue
            starts, stops = points[np.append(0, breaks)], points[np.append(breaks - 1, len(points) - 1)] + 1
            shift = np.zeros(layers.source.n_agents, dtype=np.int64)
            shift[points] = points - np.arange(len(points))
            found.append((points, shift, list(zip(starts.tolist(), stops.tolist()))))
        object.__setattr__(layers, "_runs", found)
    return layers._runs


def _adjacency(n_points: int, faces: np.ndarray):
    edges = face_edges(faces)
    rows, cols = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
    return coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_points, n_points)).tocsr()


def seam_points(layers: GraphLayers) -> np.ndarray:
    """Points of faces that span two or more parts."""
    labels = layers.segmentation.labels[layers.faces]
    spanning = np.any(labels != labels[:, :1], axis=1)
    return np.unique(layers.faces[spanning])


def _seam_operator(layers: GraphLayers):
    """(involved points, those smoothed, A, c): SEAM_PASSES passes of smoothing composed into one
    affine map, smoothed positions = A @ involved positions + c; made once per layers."""
    adjacency = _adjacency(layers.source.n_agents, layers.faces)
    zone = np.zeros(layers.source.n_agents, dtype=bool)
    zone[seam_points(layers)] = True
    for _ in range(SEAM_RINGS):
        zone |= (adjacency @ zone.astype(float)) > 0
    # the passes read the zone and its neighbors only: work on that block of points
    involved = np.flatnonzero(zone | ((adjacency @ zone.astype(float)) > 0))
    inner = zone[involved]
    degree = np.asarray(adjacency.sum(axis=1)).ravel()[involved]
    mean_of_neighbors = adjacency[involved][:, involved].multiply(1.0 / np.maximum(degree, 1)[:, None])
    # one pass: inner rows take their neighbors' mean displacement, the others keep theirs
    one_pass = (diags(inner.astype(float)) @ mean_of_neighbors + diags((~inner).astype(float))).tocsr()
    composed = identity(len(involved), format="csr")
    for _ in range(SEAM_PASSES):
        composed = one_pass @ composed
    composed = composed[np.flatnonzero(inner)].tocsr()
    rest = layers.source.positions.mean(axis=0)[involved]
    return SEAM_PASSES, involved, involved[inner], composed, rest[inner] - composed @ rest


def _smooth_seams(positions: np.ndarray, layers: GraphLayers) -> np.ndarray:
    if layers._seams is None or layers._seams[0] != SEAM_PASSES:
        object.__setattr__(layers, "_seams", _seam_operator(layers))
    _, involved, smoothed, composed, offset = layers._seams
    frames, _, d = positions.shape
    if len(smoothed) == 0:
        return positions
    block = max(1, SEAM_BLOCK_BYTES // (8 * d * len(involved)))
    for start in range(0, frames, block):
        chunk = positions[start : start + block]
        n = len(chunk)
        points = np.take(chunk, involved, axis=1).transpose(1, 0, 2).reshape(len(involved), n * d)
        chunk[:, smoothed] = (composed @ points).reshape(len(smoothed), n, d).transpose(1, 0, 2) + offset
    return positions


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
