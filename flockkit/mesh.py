"""Animated meshes (paper 002): a Motion whose agents are the vertices of a mesh, with its faces.

Readers: glTF 2.0 (skinned meshes and morph targets, through ``flockkit._gltf``), sequences of
OBJ files (one per frame, fixed topology) and USD meshes with time-sampled points (extra ``usd``).
"""

from __future__ import annotations

import glob as globbing
import math
import os
import re
from pathlib import Path

import attrs
import numpy as np

from . import _files, _gltf, _npzfile, validate
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


def fan_triangles(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Triangles (F, 3) of polygons given as vertex counts and their concatenated indices, each
    polygon split into a fan from its first corner (polygons of fewer than 3 corners dropped)."""
    starts = np.cumsum(counts) - counts
    fans = np.maximum(counts - 2, 0)
    polygon = np.repeat(np.arange(len(counts)), fans)
    corner = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1
    first = starts[polygon]
    return np.column_stack([indices[first], indices[first + corner], indices[first + corner + 1]]).reshape(-1, 3)


def list_clips(path, *, allow_outside: bool = False) -> dict[str, float]:
    """The clips of an animated-mesh file and their durations in seconds: a glTF file's
    animations, a USD stage's time range (one clip, named after the file), an OBJ sequence (one,
    of no duration: its rate is the reader's `fps`). `allow_outside` as for
    :func:`read_mesh_animation`."""
    path = Path(path)
    suffix = _format(path)
    if suffix in GLTF_SUFFIXES:
        return _gltf.Document(path, allow_outside=allow_outside).clips()
    if suffix in USD_SUFFIXES:
        stage = _usd_stage(path, allow_outside)
        return {path.stem: (stage.GetEndTimeCode() - stage.GetStartTimeCode()) / stage.GetTimeCodesPerSecond()}
    _obj_files(str(path))
    return {path.stem: 0.0}


def _format(path: Path) -> str:
    """The suffix naming `path`'s format ("obj" for a folder or a glob of OBJ files); a
    ValidationError for any other."""
    text = str(path)
    if path.is_dir() or (not path.exists() and any(c in text for c in "*?[")):
        return ".obj"
    suffix = path.suffix.lower()
    if suffix not in GLTF_SUFFIXES + USD_SUFFIXES + (".obj",):
        raise ValidationError(
            f"{path}: unknown mesh animation format {suffix or 'without a suffix'!r}; expected .glb, .gltf, .usda, "
            ".usdc, .usdz, .usd, .obj, a folder of .obj files or a glob"
        )
    return suffix


def read_mesh_animation(path, *, clip=None, fps: float = 30.0, allow_outside: bool = False) -> AnimatedMesh:
    """An animated mesh from `path`, sampled at `fps` frames a second.

    - glTF 2.0 (.glb, .gltf with GLB, external or data-URI buffers): every mesh of the default
      scene, morph targets weighted and skinned meshes skinned (linear blend skinning), for the
      named `clip` (a name or an index; default the first; ``list_clips`` names them).
    - OBJ sequences (a folder of .obj files, or a glob such as ``frames/*.obj``): one file per
      frame in natural order (frame2 before frame10), the same faces in every one; `fps` is the
      sequence's rate. A path that exists is never read as a glob, whatever its characters.
    - USD (.usda, .usdc, .usdz, .usd; extra ``usd``): every ``UsdGeom.Mesh`` with its
      time-sampled points, in world space, sampled at `fps` over the stage's time range.

    Faces are triangles or quads (larger polygons are split into a fan of triangles).

    Files are read as untrusted (see docs/security.md): the files a glTF or USD file refers to
    must lie inside its folder, unless `allow_outside` is True; an OBJ folder's files must be
    regular files inside it. Sizes are checked against the memory budget
    (``flockkit.validate.memory_limit``) before anything is sampled.
    """
    fps = number(fps, "read_mesh_animation: fps", minimum=0, strict=True)
    path = Path(path)
    suffix = _format(path)
    if suffix in GLTF_SUFFIXES:
        name, positions, faces, clip_name = _gltf.mesh_animation(path, clip, fps, allow_outside=allow_outside)
        return AnimatedMesh(motion=_motion(positions, fps, path), faces=faces, name=f"{name}:{clip_name}")
    if suffix in USD_SUFFIXES:
        return _read_usd(path, fps, allow_outside)
    return _read_obj_sequence(str(path), fps)


def _motion(positions, fps, source) -> Motion:
    try:
        return Motion(positions=positions, dt=1.0 / fps)
    except ValidationError as exc:
        raise ValidationError(f"{source}: {exc}") from None


# -- OBJ sequences ------------------------------------------------------------------------------


def _natural(path: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", Path(path).name)]


def _obj_files(pattern: str) -> list[str]:
    """The frames of an OBJ sequence in natural order: a folder's .obj files, a glob's matches,
    or one file. Each must be a regular file, and a link in a folder must stay inside it."""
    path = Path(pattern)
    if path.is_dir():
        files = [str(f) for f in path.iterdir() if f.suffix.lower() == ".obj"]
    elif path.exists():
        files = [pattern]
    else:
        files = globbing.glob(pattern)
    if not files:
        raise FileNotFoundError(f"{pattern}: no .obj files")
    for file in files:
        folder = Path(file).parent.resolve()
        if not Path(file).resolve().is_relative_to(folder):
            raise FileFormatError(f"{file}: a link that leads outside {folder}; an OBJ sequence stays in its folder")
    return sorted(files, key=_natural)


def _read_obj_sequence(pattern: str, fps: float) -> AnimatedMesh:
    files = _obj_files(pattern)
    frames, faces = [], None
    for file in files:
        points, polygons = _read_obj(file)
        if faces is None:
            faces, first = polygons, file
            validate.allocation(len(files) * points.size, f"{pattern}: {len(files)} frames of {len(points)} vertices")
        elif len(points) != len(frames[0]) or not np.array_equal(polygons, faces):
            raise FileFormatError(
                f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
                f"{len(frames[0])} and {len(faces)}); an OBJ sequence keeps one topology"
            )
        frames.append(points)
    return AnimatedMesh(motion=_motion(np.stack(frames), fps, pattern), faces=faces, name=Path(files[0]).stem)


_MAX_VERTEX = 2**40  # far above any file's vertex count, far below numpy's int64


def _read_obj(file) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) and faces (F, 3 or 4) of one OBJ file: ``v x y z`` lines (a fourth
    coordinate or vertex colours after them are ignored) and ``f`` lines of 1-based or negative
    (relative) indices; other lines are ignored."""
    points, polygons = [], []
    for number_, line in enumerate(_files.read_text(file).splitlines(), 1):
        fields = line.split()
        if not fields or fields[0] not in ("v", "f"):
            continue
        try:
            if fields[0] == "v":
                if len(fields) < 4:
                    raise ValueError
                points.append([float(v) for v in fields[1:4]])
                continue
            corners = [int(f.split("/")[0]) for f in fields[1:]]
            if len(corners) < 3 or 0 in corners:
                raise ValueError
        except ValueError:
            raise FileFormatError(
                f"{file}, line {number_}: not an OBJ vertex (v x y z) or face (f and 3 or more vertex numbers from 1, "
                f"or negative ones): {line.strip()[:80]!r}"
            ) from None
        corners = [c - 1 if c > 0 else len(points) + c for c in corners]  # 1-based, or relative
        if min(corners) < 0 or max(corners) > _MAX_VERTEX:
            raise FileFormatError(f"{file}, line {number_}: a face refers to a vertex that no OBJ file can hold")
        if len(corners) in (3, 4):
            polygons.append(corners)
        else:
            polygons += [[corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1)]
    if not points:
        raise FileFormatError(f"{file}: no vertices (not an OBJ file?)")
    points = np.array(points, dtype=float)
    if not np.all(np.isfinite(points)):
        raise FileFormatError(f"{file}: vertices must have finite coordinates")
    triangles = [p for p in polygons if len(p) == 3]
    quads = [p for p in polygons if len(p) == 4]
    if triangles and quads:  # one face width per mesh: split the quads
        triangles += [q[:3] for q in quads] + [[q[0], q[2], q[3]] for q in quads]
        quads = []
    faces = np.array(quads or triangles or np.zeros((0, 3)), dtype=np.int64).reshape(-1, 4 if quads else 3)
    if len(faces) and faces.max() >= len(points):
        raise FileFormatError(f"{file}: a face refers to vertex {faces.max() + 1}; the file has {len(points)}")
    return points, faces


# -- USD ----------------------------------------------------------------------------------------


def _usd_stage(path, allow_outside: bool = False):
    """The USD stage at `path`, opened only after every layer it would compose (sublayers,
    references, payloads, value clips) is found to be a regular file inside its folder; once open,
    the layers it uses are checked again. `allow_outside` lifts the folder rule."""
    try:
        from pxr import Sdf, Tf, Usd
    except ImportError:
        raise MissingDependencyError("reading USD needs usd-core: pip install 'flockkit[usd]'") from None
    path = Path(path)
    os.close(_files.open_regular(path))
    try:
        if not allow_outside:
            _confine_layers(path, Sdf)
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as exc:
        raise FileFormatError(f"{path}: not a USD stage usd-core can open: {str(exc).strip()[:200]}") from None
    if stage is None:
        raise FileFormatError(f"{path}: not a USD stage usd-core can open")
    folder = path.parent.resolve()
    for layer in stage.GetUsedLayers(includeClipLayers=True):
        real = layer.realPath.split("[", 1)[0]  # a layer inside a package: package.usdz[layer.usdc]
        if real and not allow_outside and not Path(real).resolve().is_relative_to(folder):
            raise FileFormatError(f"{path}: composes layer {real}, outside {folder}; flockkit reads only files inside "
                                  "a stage's folder")  # fmt: skip
    return stage


def _confine_layers(path: Path, Sdf) -> None:
    """Walk the layers `path` refers to, checking each reference (``flockkit._files.confined``)
    and each file (a regular file) before usd-core opens it."""
    seen, todo = set(), [path.resolve()]
    while todo:
        file = todo.pop()
        if file in seen:
            continue
        seen.add(file)
        os.close(_files.open_regular(file))
        layer = Sdf.Layer.FindOrOpen(str(file))
        if layer is None:
            raise FileFormatError(f"{file}: not a USD layer usd-core can open")
        for reference in [*layer.GetCompositionAssetDependencies(), *_clip_assets(layer, Sdf)]:
            target = _files.confined(file.parent, reference, source=file, where="a layer it composes")
            if file.suffix.lower() != ".usdz" and target.exists():  # a package's layers lie inside it
                todo.append(target)


def _clip_assets(layer, Sdf) -> list[str]:
    """The asset paths of the value clips a layer's prims name (their ``clips`` metadata)."""
    found = []

    def visit(spec_path):
        spec = layer.GetPrimAtPath(spec_path) if spec_path.IsPrimPath() else None
        if spec is None or not spec.HasInfo("clips"):
            return
        for clip_set in dict(spec.GetInfo("clips")).values():
            found.extend(getattr(a, "path", str(a)) for a in clip_set.get("assetPaths", []))
            for key in ("manifestAssetPath", "templateAssetPath"):
                if clip_set.get(key):
                    found.append(getattr(clip_set[key], "path", str(clip_set[key])).replace("#", "0"))

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return [f for f in found if f]


def _read_usd(path: Path, fps: float, allow_outside: bool) -> AnimatedMesh:
    from pxr import Usd, UsdGeom

    stage = _usd_stage(path, allow_outside)
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise ValidationError(f"{path}: the stage has no UsdGeom.Mesh")
    rate = stage.GetTimeCodesPerSecond()
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if not (rate > 0 and math.isfinite(start) and math.isfinite(end) and end >= start):
        raise FileFormatError(
            f"{path}: the stage's time range {start:g}..{end:g} at {rate:g} codes a second is not one"
        )
    points = sum(len(mesh.GetPointsAttr().Get(Usd.TimeCode(start)) or []) for mesh in meshes)
    validate.allocation(((end - start) / rate + 1e-9) * fps * points * 3 * 2,
                        f"{path}: {(end - start) / rate:g} s at {fps:g} fps of {points} points")  # fmt: skip
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
        if np.any(counts < 0) or counts.sum() != len(indices) or np.any(indices < 0) or np.any(
                indices >= len(frames[0])):  # fmt: skip
            raise FileFormatError(f"{path}: {mesh.GetPath()}'s faceVertexCounts and faceVertexIndices do not describe "
                                  f"faces of its {len(frames[0])} points")  # fmt: skip
        positions.append(np.stack(frames))
        faces.append(fan_triangles(counts, indices) + count)
        count += positions[-1].shape[1]
    return AnimatedMesh(motion=_motion(np.concatenate(positions, axis=1), fps, path), faces=np.concatenate(faces),
                        name=path.stem)  # fmt: skip
