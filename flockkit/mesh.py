"""Animated meshes (paper 002): a Motion whose agents are the vertices of a mesh, with its faces.

Readers: glTF 2.0 (skinned meshes and morph targets, through ``flockkit._gltf``), sequences of
OBJ files (one per frame, fixed topology) and USD meshes with time-sampled points (extra ``usd``).
"""

from __future__ import annotations

import glob as globbing
import re
from pathlib import Path

import attrs
import numpy as np

from . import _gltf, _npzfile
from ._arrays import readonly_int
from .errors import FileFormatError, MissingDependencyError, ValidationError
from .motion import Motion
from .validate import number

__all__ = ["AnimatedMesh", "read_mesh_animation", "list_clips", "face_edges"]

MESH_FORMAT_VERSION = 1
GLTF_SUFFIXES, USD_SUFFIXES = (".glb", ".gltf"), (".usda", ".usdc", ".usdz", ".usd")


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


def list_clips(path) -> dict[str, float]:
    """The clips of an animated-mesh file and their durations in seconds: a glTF file's
    animations, a USD stage's time range (one clip, named after the file), an OBJ sequence (one)."""
    path = Path(path)
    if path.suffix.lower() in GLTF_SUFFIXES:
        return _gltf.Document(path).clips()
    if path.suffix.lower() in USD_SUFFIXES:
        stage = _usd_stage(path)
        return {path.stem: (stage.GetEndTimeCode() - stage.GetStartTimeCode()) / stage.GetTimeCodesPerSecond()}
    return {path.stem: 0.0}


def read_mesh_animation(path, *, clip=None, fps: float = 30.0) -> AnimatedMesh:
    """An animated mesh from `path`, sampled at `fps` frames a second.

    - glTF 2.0 (.glb, .gltf with GLB, external or data-URI buffers): every mesh of the default
      scene, morph targets weighted and skinned meshes skinned (linear blend skinning), for the
      named `clip` (a name or an index; default the first; ``list_clips`` names them).
    - OBJ sequences (a folder of .obj files, or a glob such as ``frames/*.obj``): one file per
      frame in natural order (frame2 before frame10), the same faces in every one; `fps` is the
      sequence's rate.
    - USD (.usda, .usdc, .usdz; extra ``usd``): every ``UsdGeom.Mesh`` with its time-sampled
      points, in world space, sampled at `fps` over the stage's time range.

    Faces are triangles or quads (larger polygons are split into a fan of triangles).
    """
    fps = number(fps, "read_mesh_animation: fps", minimum=0, strict=True)
    text = str(path)
    if any(c in text for c in "*?[") or Path(path).is_dir():
        return _read_obj_sequence(text, fps)
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in GLTF_SUFFIXES:
        name, positions, faces, clip_name = _gltf.mesh_animation(path, clip, fps)
        return AnimatedMesh(motion=_motion(positions, fps, path), faces=faces, name=f"{name}:{clip_name}")
    if suffix in USD_SUFFIXES:
        return _read_usd(path, fps)
    if suffix == ".obj":
        return _read_obj_sequence(text, fps)
    raise ValidationError(
        f"{path}: unknown mesh animation format {suffix!r}; expected .glb, .gltf, .usda, .usdc, .usdz, a folder "
        "of .obj files or a glob"
    )


def _motion(positions, fps, source) -> Motion:
    try:
        return Motion(positions=positions, dt=1.0 / fps)
    except ValidationError as exc:
        raise ValidationError(f"{source}: {exc}") from None


# -- OBJ sequences ------------------------------------------------------------------------------


def _natural(path: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", Path(path).name)]


def _read_obj_sequence(pattern: str, fps: float) -> AnimatedMesh:
    files = sorted(globbing.glob(str(Path(pattern) / "*.obj")) if Path(pattern).is_dir() else globbing.glob(pattern),
                   key=_natural)  # fmt: skip
    if not files:
        raise FileNotFoundError(f"{pattern}: no .obj files")
    frames, faces = [], None
    for file in files:
        points, polygons = _read_obj(file)
        if faces is None:
            faces, first = polygons, file
        elif len(points) != len(frames[0]) or not np.array_equal(polygons, faces):
            raise FileFormatError(
                f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
                f"{len(frames[0])} and {len(faces)}); an OBJ sequence keeps one topology"
            )
        frames.append(points)
    return AnimatedMesh(motion=_motion(np.stack(frames), fps, pattern), faces=faces, name=Path(files[0]).stem)


def _read_obj(file) -> tuple[np.ndarray, np.ndarray]:
    points, polygons = [], []
    with open(file, encoding="utf-8", errors="replace") as handle:
        for number_, line in enumerate(handle, 1):
            fields = line.split()
            if not fields:
                continue
            try:
                if fields[0] == "v":
                    points.append([float(v) for v in fields[1:4]])
                elif fields[0] == "f":
                    corners = [int(f.split("/")[0]) for f in fields[1:]]
                    corners = [c - 1 if c > 0 else len(points) + c for c in corners]  # 1-based, or relative
                    if len(corners) in (3, 4):
                        polygons.append(corners)
                    else:
                        polygons += [[corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1)]
            except ValueError:
                raise FileFormatError(
                    f"{file}, line {number_}: not an OBJ vertex or face: {line.strip()[:80]!r}"
                ) from None
    if not points:
        raise FileFormatError(f"{file}: no vertices (not an OBJ file?)")
    points = np.array(points, dtype=float)
    if points.shape[1] != 3:
        raise FileFormatError(f"{file}: vertices must have 3 coordinates")
    triangles = [p for p in polygons if len(p) == 3]
    quads = [p for p in polygons if len(p) == 4]
    if triangles and quads:  # one face width per mesh: split the quads
        triangles += [q[:3] for q in quads] + [[q[0], q[2], q[3]] for q in quads]
        quads = []
    faces = np.array(quads or triangles or np.zeros((0, 3)), dtype=np.int64).reshape(-1, 4 if quads else 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(points)):
        raise FileFormatError(f"{file}: a face refers to a vertex that does not exist")
    return points, faces


# -- USD ----------------------------------------------------------------------------------------


def _usd_stage(path):
    try:
        from pxr import Usd
    except ImportError:
        raise MissingDependencyError("reading USD needs usd-core: pip install 'flockkit[usd]'") from None
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such file")
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise FileFormatError(f"{path}: not a USD stage usd-core can open")
    return stage


def _read_usd(path: Path, fps: float) -> AnimatedMesh:
    from pxr import Usd, UsdGeom

    stage = _usd_stage(path)
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise ValidationError(f"{path}: the stage has no UsdGeom.Mesh")
    rate = stage.GetTimeCodesPerSecond()
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    codes = start + np.arange(0.0, (end - start) / rate + 1e-9, 1.0 / fps) * rate
    positions, faces, count = [], [], 0
    cache = UsdGeom.XformCache()
    for mesh in meshes:
        frames = []
        for code in codes:
            time = Usd.TimeCode(float(code))
            points = np.array(mesh.GetPointsAttr().Get(time), dtype=float).reshape(-1, 3)
            if frames and len(points) != len(frames[0]):
                raise FileFormatError(
                    f"{path}: {mesh.GetPath()} has {len(points)} points at time {code:g} and {len(frames[0])} at the "
                    "start; an animated mesh keeps one topology"
                )
            cache.SetTime(time)
            matrix = np.array(cache.GetLocalToWorldTransform(mesh.GetPrim()), dtype=float)  # row vectors: p @ M
            frames.append(points @ matrix[:3, :3] + matrix[3, :3])
        counts = np.array(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        indices = np.array(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
        starts = np.cumsum(counts) - counts
        triangles = [
            [indices[s], indices[s + i], indices[s + i + 1]] for s, c in zip(starts, counts) for i in range(1, c - 1)
        ]
        positions.append(np.stack(frames))
        faces.append(np.array(triangles, dtype=np.int64).reshape(-1, 3) + count)
        count += positions[-1].shape[1]
    return AnimatedMesh(motion=_motion(np.concatenate(positions, axis=1), fps, path), faces=np.concatenate(faces),
                        name=path.stem)  # fmt: skip
