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

Up axes and units: a mesh says which of its axes is up (`up_axis`) and how many metres one of its
units is (`meters_per_unit`), as its file states them (glTF: y up, metres; a USD stage: its
upAxis and metersPerUnit; an OBJ sequence: y up by convention and no unit) or as the caller
states them where the file is wrong or silent (the Fox of the glTF samples is modelled in
centimetres). flockkit's own analysis and exports take z up and metres (``FLOCKKIT_UP_AXIS``,
``FLOCKKIT_METERS_PER_UNIT``): :meth:`AnimatedMesh.to_flockkit_axes` converts a mesh once, before
it is analysed or placed, with the one conversion every part of flockkit uses,
:func:`conversion_matrix`. Nothing is converted or guessed silently: a unit that no one stated
is refused, and a size no object plausibly has gets a hint (:func:`unit_hint`), never a change.

Skins: a mesh read from a skinned character carries its skin (:class:`MeshSkin`): the joints of
its skeleton with their hierarchy, and each vertex's joints and weights. That is what the file
already says about which vertices move together, and segmenters that declare
``Capabilities(skin=True)`` read it. A skin names no coordinates, so it holds in any axes.
"""

from __future__ import annotations

import math
import warnings

import attrs
import numpy as np

from . import _npzfile, validate
from ._arrays import readonly_float, readonly_int
from .errors import FileFormatError, FlockkitWarning, ValidationError
from .motion import Motion

__all__ = [
    "AnimatedMesh",
    "MeshSkin",
    "face_edges",
    "fan_triangles",
    "object_size",
    "weld_map",
    "WELD_TOLERANCE",
    "conversion_matrix",
    "unit_hint",
    "check_up_axis",
    "check_meters_per_unit",
    "UP_AXES",
    "UNITS",
    "FLOCKKIT_UP_AXIS",
    "FLOCKKIT_METERS_PER_UNIT",
]

# Version 2 adds the up axis and the unit; a version 1 file has neither and loads as flockkit's
# convention (z up, metres), which is how flockkit used every mesh when it wrote those files.
# Version 3 adds the skin, where the mesh has one (versions 1 and 2 load without one).
MESH_FORMAT_VERSION = 3
MESH_FORMAT_VERSIONS = (1, 2, 3)
# Each vertex's skin weights must sum to 1 within this (readers normalize what files round).
SKIN_WEIGHT_TOLERANCE = 1e-6

# flockkit's own axes, which its analysis (footprints on the ground plane, headings about +z,
# feature arrows on the ground) and its exports (USD upAxis Z, metersPerUnit) take: z up, metres.
FLOCKKIT_UP_AXIS = "z"
FLOCKKIT_METERS_PER_UNIT = 1.0
UP_AXES = ("x", "y", "z")
# Units a caller may name instead of giving metres per unit (the SI prefixes and the inch and
# foot of 1959, exactly).
UNITS = {"km": 1000.0, "m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}
# Sizes (metres) outside which an object (a plant, an animal, a person, a building) is more likely
# in another unit than its file says: what earns a hint. Never applied.
PLAUSIBLE_SIZE = (0.005, 50.0)
# The quarter turn that brings each up axis onto +z, the others kept right-handed: y up turns
# about +x, (x, y, z) -> (x, -z, y), as Blender's glTF and USD importers turn a y-up file (glTF's
# +z forward becomes -y); x up turns about -y, (x, y, z) -> (-z, y, x).
_UP_TURNS = {
    "x": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "z": np.eye(3),
}
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


def check_up_axis(value, field: str) -> str:
    """`value` as an up axis, "x", "y" or "z" (any case: USD writes "Y" and "Z"), or a
    ValidationError naming `field`."""
    if isinstance(value, str) and value.lower() in UP_AXES:
        return value.lower()
    axes = ", ".join(map(repr, UP_AXES))
    raise ValidationError(f"{field} must be one of {axes} (the axis pointing up); got {value!r}")


def check_meters_per_unit(value, field: str, *, optional: bool = False) -> float | None:
    """`value` as metres per unit: a finite number above 0, or a unit's name in ``UNITS`` ("cm");
    None (no unit stated) where `optional`. A ValidationError naming `field` otherwise."""
    if value is None and optional:
        return None
    if isinstance(value, str):
        if value in UNITS:
            return UNITS[value]
        names = ", ".join(map(repr, UNITS))
        raise ValidationError(f"{field} must be metres per unit (a number above 0) or one of {names}; got {value!r}")
    return validate.number(value, field, minimum=0, strict=True)


def conversion_matrix(up_axis: str, meters_per_unit) -> np.ndarray:
    """The matrix (3, 3) taking an asset's coordinates (up along `up_axis`, `meters_per_unit`
    metres a unit, or a unit's name) to flockkit's (z up, metres): ``flockkit = M @ asset``, the
    quarter turn that brings the up axis onto +z (y up: (x, y, z) -> (x, -z, y), as Blender
    imports y-up files) times the unit. The one conversion between an asset's axes and
    flockkit's: meshes are converted with it and crowds place characters with it."""
    turn = _UP_TURNS[check_up_axis(up_axis, "up_axis")]
    scale = check_meters_per_unit(meters_per_unit, "meters_per_unit")
    return turn * scale


def unit_hint(size: float, meters_per_unit: float, what: str) -> str | None:
    """A hint where `what`, `size` units across at `meters_per_unit` metres a unit, has a size
    no object plausibly has (outside PLAUSIBLE_SIZE metres): how large each named unit that gives
    a plausible size would make it. None where the size is plausible. Only ever shown."""
    meters = size * meters_per_unit
    low, high = PLAUSIBLE_SIZE
    if not math.isfinite(meters) or low <= meters <= high or size <= 0:
        return None
    others = [f"{name} ({factor:g} m a unit): {size * factor:.3g} m"
              for name, factor in UNITS.items() if low <= size * factor <= high]  # fmt: skip
    return (
        f"{what} is {size:.4g} units across, {meters:.4g} m at {meters_per_unit:g} m a unit; if its file is in "
        f"another unit, state it with meters_per_unit= (" + ("; ".join(others) or "no named unit fits") + ")"
    )


def _joint_names(value) -> tuple:
    if isinstance(value, str) or not isinstance(value, list | tuple | np.ndarray):
        raise ValidationError(f"MeshSkin.joint_names must be a sequence of names; got {type(value).__name__}")
    return tuple(value)


def _skin_parents(value) -> np.ndarray:
    parents = readonly_int(value, field="MeshSkin.parents")
    if parents.ndim != 1 or len(parents) == 0:
        raise ValidationError(f"MeshSkin.parents must be a non-empty 1D array; got shape {parents.shape}")
    bad = np.flatnonzero((parents < -1) | (parents >= np.arange(len(parents))))
    if len(bad):
        j = int(bad[0])
        raise ValidationError(
            f"MeshSkin.parents[{j}] = {int(parents[j])}: each joint's parent must come before it (or be -1 for a root)"
        )
    return parents


@attrs.frozen(kw_only=True, eq=False)
class MeshSkin:
    """What moves each vertex of a skinned mesh: the skeleton's joints, their hierarchy, and each
    vertex's joints and weights (linear blend skinning's influences).

    Parameters
    ----------
    joint_names : sequence of str
        The joints (J), non-empty distinct names; `parents` and `joints` index them.
    parents : (J,) int
        Each joint's parent, -1 for a root; a parent comes before its children.
    joints : (V, K) int
        Each vertex's K joints (0..J-1).
    weights : (V, K)
        Their weights: finite, >= 0, each vertex's summing to 1 (within SKIN_WEIGHT_TOLERANCE).
    """

    joint_names: tuple = attrs.field(converter=_joint_names)
    parents: np.ndarray = attrs.field(converter=_skin_parents)
    joints: np.ndarray = attrs.field(converter=lambda v: readonly_int(v, field="MeshSkin.joints"))
    weights: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="MeshSkin.weights"))

    def __attrs_post_init__(self):
        j = len(self.parents)
        names = self.joint_names
        if len(names) != j or not all(isinstance(n, str) and n for n in names) or len(set(names)) != j:
            raise ValidationError(f"MeshSkin.joint_names must be {j} distinct non-empty strings, one per joint")
        if self.joints.ndim != 2 or self.joints.shape[0] == 0 or self.joints.shape[1] == 0:
            raise ValidationError(f"MeshSkin.joints must have shape (V, K), V, K >= 1; got {self.joints.shape}")
        if self.joints.min() < 0 or self.joints.max() >= j:
            raise ValidationError(
                f"MeshSkin.joints must index the {j} joints; got {self.joints.min()}..{self.joints.max()}"
            )
        if self.weights.shape != self.joints.shape:
            raise ValidationError(
                f"MeshSkin.weights must have the shape of joints {self.joints.shape}; got {self.weights.shape}"
            )
        if not np.all(np.isfinite(self.weights)) or self.weights.min() < 0:
            raise ValidationError("MeshSkin.weights must be finite and >= 0")
        off = np.abs(self.weights.sum(axis=1) - 1.0)
        if off.max() > SKIN_WEIGHT_TOLERANCE:
            v = int(np.argmax(off))
            raise ValidationError(
                f"MeshSkin.weights of each vertex must sum to 1; vertex {v}'s sum to {self.weights[v].sum():.9g}"
            )

    @property
    def n_vertices(self) -> int:
        """V, the number of vertices."""
        return len(self.joints)

    @property
    def n_joints(self) -> int:
        """J, the number of joints."""
        return len(self.parents)

    def weight_matrix(self) -> np.ndarray:
        """Each vertex's weight per joint (V, J), zero where it does not follow the joint (a joint
        named twice for one vertex gets the sum)."""
        flat = np.arange(self.n_vertices)[:, None] * self.n_joints + self.joints
        return np.bincount(flat.ravel(), self.weights.ravel(), minlength=self.n_vertices * self.n_joints).reshape(
            -1, self.n_joints
        )

    def dominant(self) -> np.ndarray:
        """(V,) each vertex's joint of largest weight (the smallest such joint where weights tie)."""
        return np.argmax(self.weight_matrix(), axis=1)

    def take(self, vertices) -> MeshSkin:
        """The skin of `vertices` (indices, in that order) alone: what a subset of the mesh's
        points (welded copies dropped, say) keeps."""
        vertices = readonly_int(vertices, field="MeshSkin.take: vertices")
        if vertices.ndim != 1 or (len(vertices) and (vertices.min() < 0 or vertices.max() >= self.n_vertices)):
            raise ValidationError(f"MeshSkin.take: vertices must be indices 0..{self.n_vertices - 1}")
        return MeshSkin(joint_names=self.joint_names, parents=self.parents, joints=self.joints[vertices],
                        weights=self.weights[vertices])  # fmt: skip

    def check_fits(self, n_points: int, what: str) -> None:
        """ValidationError naming `what` unless the skin has one row per point of `n_points`."""
        if self.n_vertices != n_points:
            raise ValidationError(f"{what}: the skin has {self.n_vertices} vertices but there are {n_points} points")

    def __eq__(self, other):
        if not isinstance(other, MeshSkin):
            return NotImplemented
        return (
            self.joint_names == other.joint_names
            and np.array_equal(self.parents, other.parents)
            and np.array_equal(self.joints, other.joints)
            and np.array_equal(self.weights, other.weights)
        )

    __hash__ = None


def _skin_field(value) -> MeshSkin | None:
    if value is not None and not isinstance(value, MeshSkin):
        raise ValidationError(f"AnimatedMesh.skin must be a flockkit.mesh.MeshSkin or None; got {type(value).__name__}")
    return value


def _up_axis_field(value) -> str:
    return check_up_axis(value, "AnimatedMesh.up_axis")


def _unit_field(value) -> float | None:
    return check_meters_per_unit(value, "AnimatedMesh.meters_per_unit", optional=True)


@attrs.frozen(kw_only=True, eq=False)
class AnimatedMesh:
    """An animated mesh: `motion` (T, V, 3) of its vertices, `faces` (F, 3 or 4) indexing them,
    a `name`, and the axes its coordinates are in: `up_axis` ("x", "y" or "z") and
    `meters_per_unit` (a number, or None where no one has stated the unit: an OBJ sequence's).
    The defaults are flockkit's convention (z up, metres); ``flockkit.io.read_mesh_animation``
    reports what each file says. :meth:`to_flockkit_axes` converts. `skin` (a :class:`MeshSkin`
    with one row per vertex, or None) is what moves the vertices where the source is a skinned
    character: ``read_mesh_animation`` reads it from a glTF file whose every mesh one skeleton
    moves."""

    motion: Motion
    faces: np.ndarray = attrs.field(converter=faces_array)
    name: str = attrs.field(default="mesh", converter=str)
    up_axis: str = attrs.field(default=FLOCKKIT_UP_AXIS, converter=_up_axis_field)
    meters_per_unit: float | None = attrs.field(default=FLOCKKIT_METERS_PER_UNIT, converter=_unit_field)
    skin: MeshSkin | None = attrs.field(default=None, converter=_skin_field)

    def __attrs_post_init__(self):
        if not isinstance(self.motion, Motion):
            raise ValidationError(f"AnimatedMesh.motion must be a flockkit.Motion; got {type(self.motion).__name__}")
        if self.skin is not None:
            self.skin.check_fits(self.motion.n_agents, "AnimatedMesh.skin")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= self.motion.n_agents):
            raise ValidationError(
                f"AnimatedMesh.faces must index vertices 0..{self.motion.n_agents - 1}; got indices "
                f"{self.faces.min()}..{self.faces.max()}"
            )

    def edges(self) -> np.ndarray:
        """Unique undirected edges (E, 2) of the faces, smaller index first."""
        return face_edges(self.faces)

    @property
    def in_flockkit_axes(self) -> bool:
        """Whether the mesh is in flockkit's convention already (z up, metres)."""
        return self.up_axis == FLOCKKIT_UP_AXIS and self.meters_per_unit == FLOCKKIT_METERS_PER_UNIT

    def to_flockkit_axes(self, *, up_axis=None, meters_per_unit=None) -> AnimatedMesh:
        """This mesh in flockkit's axes (z up, metres): every vertex times
        :func:`conversion_matrix` of its `up_axis` and `meters_per_unit`, which the arguments
        state instead where the mesh's are wrong (a glTF file is metres by its specification,
        but the Fox of the glTF samples is modelled in centimetres: ``meters_per_unit=0.01``, or
        "cm"). Faces, name and frame time are kept; heights are then along z, where the asset's
        up axis pointed, and the asset's ground (its up coordinate 0) is z = 0. The skin is kept.

        A ValidationError where no unit is known (an OBJ sequence read without one, a value made
        with None); a FlockkitWarning with :func:`unit_hint`'s hint where the converted mesh has
        a size no object plausibly has (the Fox read as metres is 170 m across)."""
        up = self.up_axis if up_axis is None else check_up_axis(up_axis, "to_flockkit_axes: up_axis")
        unit = (
            self.meters_per_unit
            if meters_per_unit is None
            else check_meters_per_unit(meters_per_unit, "to_flockkit_axes: meters_per_unit")
        )
        if unit is None:
            raise ValidationError(
                f"{self.name}: its unit is not known (an OBJ sequence states none): pass meters_per_unit= (metres "
                f"per unit, or one of {', '.join(map(repr, UNITS))}) to to_flockkit_axes or to read_mesh_animation"
                + _size_note(object_size(self))
            )
        hint = unit_hint(object_size(self), unit, self.name)
        if hint is not None and meters_per_unit is None:
            warnings.warn(hint, FlockkitWarning, stacklevel=2)
        matrix = conversion_matrix(up, unit)
        positions = self.motion.positions @ matrix.T
        return AnimatedMesh(motion=Motion(positions=positions, dt=self.motion.dt), faces=self.faces, name=self.name,
                            up_axis=FLOCKKIT_UP_AXIS, meters_per_unit=FLOCKKIT_METERS_PER_UNIT,
                            skin=self.skin)  # fmt: skip

    def __eq__(self, other):
        if not isinstance(other, AnimatedMesh):
            return NotImplemented
        return (
            self.motion == other.motion
            and np.array_equal(self.faces, other.faces)
            and self.name == other.name
            and self.up_axis == other.up_axis
            and self.meters_per_unit == other.meters_per_unit
            and self.skin == other.skin
        )

    __hash__ = None

    def save(self, path) -> None:
        """Write to one .npz of plain arrays with JSON metadata (atomic): the frame time, name, up
        axis and unit (null where unknown) beside the arrays, and the skin where there is one
        (its joint names in the metadata, null where there is none)."""
        arrays = {**self.motion._to_arrays(), "faces": self.faces}
        metadata = {"dt": self.motion.dt, "name": self.name, "up_axis": self.up_axis,
                    "meters_per_unit": self.meters_per_unit, "skin_joint_names": None}  # fmt: skip
        if self.skin is not None:
            arrays.update({"skin_parents": self.skin.parents, "skin_joints": self.skin.joints,
                           "skin_weights": self.skin.weights})  # fmt: skip
            metadata["skin_joint_names"] = list(self.skin.joint_names)
        _npzfile.write(path, kind="mesh", version=MESH_FORMAT_VERSION, arrays=arrays, metadata=metadata)

    @classmethod
    def load(cls, path) -> AnimatedMesh:
        """Read a file written by :meth:`save`; FileFormatError naming the file and the field if it
        is not one. A file of format version 1 (no axes) loads as z up, metres."""
        arrays, header = _npzfile.read(path, kind="mesh", versions=MESH_FORMAT_VERSIONS)
        try:
            axes, skin = {}, None
            if header["version"] >= 2:
                axes = {"up_axis": header["up_axis"], "meters_per_unit": header["meters_per_unit"]}
            if header["version"] >= 3 and header["skin_joint_names"] is not None:
                if not isinstance(header["skin_joint_names"], list):
                    raise ValidationError("skin_joint_names must be a list of joint names")
                skin = MeshSkin(joint_names=header["skin_joint_names"], parents=arrays["skin_parents"],
                                joints=arrays["skin_joints"], weights=arrays["skin_weights"])  # fmt: skip
            return cls(motion=Motion._from_arrays(arrays, header.get("dt")), faces=arrays["faces"],
                       name=header.get("name", "mesh"), skin=skin, **axes)  # fmt: skip
        except (KeyError, ValidationError) as exc:
            raise FileFormatError(f"{path}: invalid animated mesh: {type(exc).__name__}: {exc}") from None


def _size_note(size: float) -> str:
    """What the named units would make an object `size` units across, for a message."""
    sizes = ", ".join(f"{size * factor:.3g} m in {name}" for name, factor in UNITS.items() if name in ("m", "cm", "in"))
    return f" (it is {size:.4g} units across: {sizes})"


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
