"""Animated meshes: a Motion whose agents are the vertices of a mesh, with its faces (the value
``flockkit.io.read_mesh_animation`` reads from glTF, OBJ sequences and USD, and that paper 002's
analysis splits into parts)."""

from __future__ import annotations

import attrs
import numpy as np

from . import _npzfile
from ._arrays import readonly_int
from .errors import FileFormatError, ValidationError
from .motion import Motion

__all__ = ["AnimatedMesh", "face_edges", "fan_triangles"]

MESH_FORMAT_VERSION = 1


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
