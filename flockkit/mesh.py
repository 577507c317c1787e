"""Animated meshes: a Motion whose agents are the vertices of a mesh, with its faces (the value
``flockkit.io.read_mesh_animation`` reads from glTF, OBJ sequences and USD, and that paper 002's
analysis splits into parts).

Welding: files often hold one point of a surface as several vertices (glTF and OBJ split a vertex
wherever its normal or texture coordinates change, and some exporters give every triangle its
own three corners: a triangle soup). Such copies sit at the same place in every frame, but
nothing in the faces says they are one point, so anything that moves vertices by their mesh
neighbours (seam smoothing) or by part would pull them apart and crack the surface.
:func:`weld_map` finds them by position: vertices that stay within a tolerance of each other in
every frame, relative to the object's size (:func:`object_size`).
"""

from __future__ import annotations

import attrs
import numpy as np

from . import _npzfile, validate
from ._arrays import readonly_int
from .errors import FileFormatError, ValidationError
from .motion import Motion

__all__ = ["AnimatedMesh", "face_edges", "fan_triangles", "object_size", "weld_map", "WELD_TOLERANCE"]

MESH_FORMAT_VERSION = 1
# Vertices that stay within this fraction of the object's size of each other in every frame are
# one point of the surface. Copies of a vertex in a file hold the same float32 position (every
# copy in the Fox, RobotExpressive and MorphStressTest coincides exactly in every frame), so any
# small fraction finds them; 1e-6 is also the gap counted as no crack.
WELD_TOLERANCE = 1e-6
# Welding tolerances are refused above this: welding joins copies of one point, it does not
# simplify a mesh (and candidate pairs grow with the square of the points within reach).
WELD_TOLERANCE_MAX = 1e-2
# Frames whose positions, with the mean position, find candidate copies before every frame is
# checked (a pair that stays together in every frame is together in these).
WELD_PROBE_FRAMES = 8


def faces_array(value, field: str = "AnimatedMesh.faces") -> np.ndarray:
    """`value` as read-only faces (F, 3 or 4) of vertex indices, or ValidationError naming `field`."""
    array = readonly_int(value, field=field)
    if array.size == 0:
        array = array.reshape(0, 3)
    if array.ndim != 2 or array.shape[1] not in (3, 4):
        raise ValidationError(f"{field} must have shape (F, 3) or (F, 4); got {array.shape}")
    return array


@attrs.frozen(kw_only=True, eq=False)
class AnimatedMesh:
    """An animated mesh: `motion` (T, V, 3) of its vertices, `faces` (F, 3 or 4) indexing them,
    and a `name`."""

    motion: Motion
    faces: np.ndarray = attrs.field(converter=faces_array)
    name: str = attrs.field(default="mesh", converter=str)

    def __attrs_post_init__(self):
        if not isinstance(self.motion, Motion):
            raise ValidationError(f"AnimatedMesh.motion must be a flockkit.Motion; got {type(self.motion).__name__}")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= self.motion.n_agents):
            raise ValidationError(
                f"AnimatedMesh.faces must index vertices 0..{self.motion.n_agents - 1}; got indices "
                f"{self.faces.min()}..{self.faces.max()}"
            )

    def edges(self) -> np.ndarray:
        """Unique undirected edges (E, 2) of the faces, smaller index first."""
        return face_edges(self.faces)

    def __eq__(self, other):
        if not isinstance(other, AnimatedMesh):
            return NotImplemented
        return self.motion == other.motion and np.array_equal(self.faces, other.faces) and self.name == other.name

    __hash__ = None

    def save(self, path) -> None:
        """Write to one .npz of plain arrays with JSON metadata (atomic)."""
        arrays = {**self.motion._to_arrays(), "faces": self.faces}
        _npzfile.write(path, kind="mesh", version=MESH_FORMAT_VERSION, arrays=arrays,
                       metadata={"dt": self.motion.dt, "name": self.name})  # fmt: skip

    @classmethod
    def load(cls, path) -> AnimatedMesh:
        """Read a file written by :meth:`save`; FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(path, kind="mesh", versions=(MESH_FORMAT_VERSION,))
        try:
            return cls(motion=Motion._from_arrays(arrays, header.get("dt")), faces=arrays["faces"],
                       name=header.get("name", "mesh"))  # fmt: skip
        except (KeyError, ValidationError) as exc:
            raise FileFormatError(f"{path}: invalid animated mesh: {type(exc).__name__}: {exc}") from None


def face_edges(faces) -> np.ndarray:
    """Unique undirected edges (E, 2) of `faces` (F, 3 or 4), smaller index first."""
    faces = np.asarray(faces)
    if not len(faces):
        return np.zeros((0, 2), dtype=np.int64)
    ring = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    return np.unique(np.sort(ring, axis=1), axis=0)


def fan_triangles(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Triangles (F, 3) of polygons given as vertex counts and their concatenated indices, each
    polygon split into a fan from its first corner (polygons of fewer than 3 corners dropped)."""
    starts = np.cumsum(counts) - counts
    fans = np.maximum(counts - 2, 0)
    polygon = np.repeat(np.arange(len(counts)), fans)
    corner = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1
    first = starts[polygon]
    return np.column_stack([indices[first], indices[first + corner], indices[first + corner + 1]]).reshape(-1, 3)


def _positions(source, what: str) -> np.ndarray:
    if isinstance(source, AnimatedMesh):
        return source.motion.positions
    if isinstance(source, Motion):
        return source.positions
    raise ValidationError(f"{what} must be a flockkit.Motion or flockkit.AnimatedMesh; got {type(source).__name__}")


def object_size(source) -> float:
    """The size of an object (a Motion or an AnimatedMesh): the largest diagonal of the box that
    holds its points in one frame. A frame's box, not the whole motion's, so that an object that
    travels is as large as one that stays in place."""
    positions = _positions(source, "object_size: source")
    if positions.shape[1] == 0:
        return 0.0
    return float(np.linalg.norm(positions.max(axis=1) - positions.min(axis=1), axis=1).max())


def weld_map(source, tolerance: float = WELD_TOLERANCE) -> np.ndarray:
    """The point each point of `source` (a Motion or an AnimatedMesh) is welded to: (N,) integers,
    the smallest index of its group, where a group is the points that stay within `tolerance`
    times :func:`object_size` of each other in every frame (joined transitively). A point with no
    copy maps to itself, so ``welds[welds] == welds`` and ``welds <= arange(N)``.

    Points that touch in some frames only (lips closed at rest that open later) are not welded:
    they move apart in the source itself. Exact copies are found by sorting, near ones with a k-d
    tree over a few frames, and every candidate pair is checked over every frame; the cost grows
    with the points times the frames."""
    positions = _positions(source, "weld_map: source")
    tolerance = validate.number(tolerance, "weld tolerance", minimum=0, maximum=WELD_TOLERANCE_MAX)
    frames, n, _ = positions.shape
    radius = tolerance * object_size(source)
    probe = np.unique(np.linspace(0, frames - 1, min(frames, WELD_PROBE_FRAMES)).round().astype(np.int64))
    # what copies share: their coordinates in the probe frames and their mean over all frames
    # (copies hold the same numbers, so the same mean; points that part in other frames do not)
    keys = np.concatenate([positions[probe].transpose(1, 0, 2).reshape(n, -1), positions.mean(axis=0)], axis=1)
    pairs = [np.zeros((0, 2), dtype=np.int64)]
    pending = np.arange(n)
    while len(pending) > 1:
        # exact copies of the keys: each joins the first point with its key, if it stays with it
        _, first, inverse = np.unique(keys[pending], axis=0, return_index=True, return_inverse=True)
        candidates = np.column_stack([pending[first][inverse.ravel()], pending])
        candidates = candidates[candidates[:, 0] != candidates[:, 1]]
        together = _together(positions, candidates, radius)
        pairs.append(candidates[together])
        if len(pending) == n and radius > 0 and len(first) > 1:
            # near copies: distinct keys within the radius in every probe frame and on average
            from scipy.spatial import cKDTree

            heads = pending[first]
            near = cKDTree(keys[heads]).query_pairs(radius, p=np.inf, output_type="ndarray")
            near = heads[near]
            pairs.append(near[_together(positions, near, radius)])
        pending = candidates[~together, 1]  # copies in the keys that part in some frame: try again
    return _smallest_of_groups(n, np.concatenate(pairs))


def _together(positions: np.ndarray, pairs: np.ndarray, radius: float) -> np.ndarray:
    """Whether each pair (P, 2) of points stays within `radius` in every frame (in chunks of pairs)."""
    out = np.empty(len(pairs), dtype=bool)
    frames, _, dims = positions.shape
    chunk = max(1, 2**21 // (frames * dims))
    for start in range(0, len(pairs), chunk):
        a, b = pairs[start : start + chunk].T
        gap = np.sum((positions[:, a] - positions[:, b]) ** 2, axis=2).max(axis=0)
        out[start : start + chunk] = gap <= radius * radius
    return out


def _smallest_of_groups(n: int, pairs: np.ndarray) -> np.ndarray:
    """Each of `n` points mapped to the smallest point of its connected component under `pairs`."""
    if not len(pairs):
        return np.arange(n)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    smallest = np.full(component.max() + 1, n, dtype=np.int64)
    np.minimum.at(smallest, component, np.arange(n))
    return smallest[component]


def resolve_weld(source, weld) -> np.ndarray | None:
    """The welding a `weld` option asks for on `source`: None (automatic) welds an AnimatedMesh
    at WELD_TOLERANCE and leaves a plain Motion (agents, not a surface) alone; False: none; True:
    WELD_TOLERANCE; a number: that tolerance (a fraction of the object's size). Returns
    :func:`weld_map`'s array, or None where nothing is welded (no option, or no copies)."""
    if weld is None:
        if not isinstance(source, AnimatedMesh):
            return None
        weld = WELD_TOLERANCE
    elif weld is False or weld is np.False_:
        return None
    elif weld is True or weld is np.True_:
        weld = WELD_TOLERANCE
    elif isinstance(weld, bool | np.bool_) or not isinstance(weld, int | float | np.integer | np.floating):
        raise ValidationError(
            f"weld must be None (automatic), True, False or a tolerance (a fraction of the object's size, "
            f"0 to {WELD_TOLERANCE_MAX:g}); got {weld!r}"
        )
    welds = weld_map(source, weld)
    return None if np.array_equal(welds, np.arange(len(welds))) else welds
