"""Files in and out: captured motion read into a Motion (wide and long text tables, (T, N, D)
.npy arrays), animated meshes (glTF, OBJ sequences, USD) and skeletal clips (glTF skins, BVH)
read for analysis and crowds, and motions exported for other tools (CSV, JSON, glTF, USD).

One module per format: ``tables``, ``gltf``, ``bvh``, ``obj``, ``usd`` (the only one that imports
usd-core). Every file is read as untrusted (docs/security.md): regular files only, the files it
names confined to its folder unless ``allow_outside=True``, and sizes checked against the memory
budget (``flockkit.validate.memory_limit``) before anything is allocated.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import validate
from ..errors import ValidationError
from ..mesh import AnimatedMesh, check_meters_per_unit, check_up_axis
from ..motion import Motion
from ..skeleton import Channel, Pose, SkeletalClip, Skeleton
from . import bvh, gltf, obj, usd
from .gltf import write_gltf
from .skin import mesh_skin
from .tables import DEFAULT_MAX_GAP, fill_gaps, read_long, read_npy, read_wide, write_csv, write_json
from .usd import USD_FPS, write_usd

__all__ = [
    "read_wide",
    "read_long",
    "read_npy",
    "read_mesh_animation",
    "list_clips",
    "read_clips",
    "fill_gaps",
    "export",
    "write_csv",
    "write_json",
    "write_gltf",
    "write_usd",
    "EXPORT_SUFFIXES",
    "DEFAULT_MAX_GAP",
    "USD_FPS",
]

GLTF_SUFFIXES, USD_SUFFIXES = (".glb", ".gltf"), (".usda", ".usdc", ".usdz", ".usd")


def list_clips(path, *, allow_outside: bool = False) -> dict[str, float]:
    """The clips of an animated-mesh file and their durations in seconds: a glTF file's
    animations, a USD stage's time range (one clip, named after the file), an OBJ sequence (one,
    of no duration: its rate is the reader's `fps`). `allow_outside` as for
    :func:`read_mesh_animation`."""
    path = Path(path)
    suffix = _format(path)
    if suffix in GLTF_SUFFIXES:
        return gltf.Document(path, allow_outside=allow_outside).clips()
    if suffix in USD_SUFFIXES:
        return {path.stem: usd.time_range(path, allow_outside=allow_outside)}
    obj.read_sequence(str(path))
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


def read_mesh_animation(path, *, clip=None, fps: float = 30.0, allow_outside: bool = False, up_axis=None,
                        meters_per_unit=None) -> AnimatedMesh:  # fmt: skip
    """An animated mesh from `path`, sampled at `fps` frames a second, in the file's own axes,
    which it reports (``AnimatedMesh.up_axis``, ``meters_per_unit``); convert it with
    ``AnimatedMesh.to_flockkit_axes`` before placing it in a scene.

    - glTF 2.0 (.glb, .gltf with GLB, external or data-URI buffers): every mesh of the default
      scene, morph targets weighted and skinned meshes skinned (linear blend skinning), for the
      named `clip` (a name or an index; default the first; ``list_clips`` names them).
    - OBJ sequences (a folder of .obj files, or a glob such as ``frames/*.obj``): one file per
      frame in natural order (frame2 before frame10), the same faces in every one; `fps` is the
      sequence's rate. A path that exists is never read as a glob, whatever its characters.
    - USD (.usda, .usdc, .usdz, .usd; extra ``usd``): every ``UsdGeom.Mesh`` with its
      time-sampled points, in world space, sampled at `fps` over the stage's time range.

    Faces are triangles or quads (larger polygons are split into a fan of triangles).

    Skins: a glTF character whose every mesh one skeleton moves (skinned by it, or hung under one
    of its nodes) is read with its skin (``AnimatedMesh.skin``, a ``flockkit.MeshSkin``: the
    skeleton's joints and parents as ``read_clips`` gives them, each vertex's joints and weights),
    which skin-aware segmenters read. Other meshes have none (None).

    Axes: glTF is y up in metres (its specification, whatever scale an asset was modelled at);
    a USD stage says its upAxis and metersPerUnit (USD's fallbacks, y and 0.01, where it does
    not); an OBJ sequence says neither: y up by convention, and no unit (None). `up_axis` ("x",
    "y", "z") and `meters_per_unit` (a number, or a name such as "cm") state them instead, where
    the file is silent or wrong (the Fox of the glTF samples is modelled in centimetres).

    Files are read as untrusted (see docs/security.md): the files a glTF or USD file refers to
    must lie inside its folder, unless `allow_outside` is True; an OBJ folder's files must be
    regular files inside it. Sizes are checked against the memory budget
    (``flockkit.validate.memory_limit``) before anything is sampled.
    """
    fps = validate.number(fps, "read_mesh_animation: fps", minimum=0, strict=True)
    stated = _stated_axes(up_axis, meters_per_unit, "read_mesh_animation")
    path = Path(path)
    suffix = _format(path)
    skin = None
    if suffix in GLTF_SUFFIXES:
        document = gltf.Document(path, allow_outside=allow_outside)
        name, positions, faces, clip_name = gltf.mesh_animation(path, clip, fps, document=document)
        name = f"{name}:{clip_name}"
        axes = {"up_axis": gltf.UP_AXIS, "meters_per_unit": gltf.METERS_PER_UNIT}
        skin = mesh_skin(document)
    elif suffix in USD_SUFFIXES:
        positions, faces, up, unit = usd.read_meshes(path, fps, allow_outside=allow_outside)
        name, axes = path.stem, {"up_axis": up, "meters_per_unit": unit}
    else:
        positions, faces, name = obj.read_sequence(str(path))
        axes = {"up_axis": obj.UP_AXIS, "meters_per_unit": None}
    return AnimatedMesh(motion=_motion(positions, fps, path), faces=faces, name=name, skin=skin, **{**axes, **stated})


def _stated_axes(up_axis, meters_per_unit, owner: str) -> dict:
    """The axes a caller states ({} where none), checked: they replace what a file says."""
    stated = {}
    if up_axis is not None:
        stated["up_axis"] = check_up_axis(up_axis, f"{owner}: up_axis")
    if meters_per_unit is not None:
        stated["meters_per_unit"] = check_meters_per_unit(meters_per_unit, f"{owner}: meters_per_unit")
    return stated


def _motion(positions, fps, source) -> Motion:
    try:
        return Motion(positions=positions, dt=1.0 / fps)
    except ValidationError as exc:
        raise ValidationError(f"{source}: {exc}") from None


def read_clips(path, *, fps=None, allow_outside: bool = False, up_axis=None,
               meters_per_unit=None) -> dict[str, SkeletalClip]:  # fmt: skip
    """Every skeletal clip in a file: glTF (.gltf, .glb: every animation of each skin) or BVH
    (.bvh: the take, named after the file).

    The skeleton reports the file's axes (``Skeleton.up_axis``, ``Skeleton.meters_per_unit``):
    glTF is y up in metres (its specification); BVH is y up by convention and states no unit
    (None), often centimetres or inches. `up_axis` and `meters_per_unit` (a number, or a name
    such as "cm" or "in") state them instead. A crowd places each character with them (see
    ``flockkit.crowd.Driver``).

    Clips keep the file's keys: a glTF clip is made of its channels (``flockkit.Channel``), each
    with its own key times and interpolation (LINEAR, STEP, CUBICSPLINE), and samples as the
    glTF 2.0 specification defines (Appendix C); a BVH clip is its frames, frame k at k / rate
    (rate: the inverse of the Frame Time, rounded to 0.01 fps, since files round the frame time:
    0.0083333 for 120 fps), each joint's rotation slerped and its translation interpolated
    linearly between frames. Nothing is resampled; ``SkeletalClip.resampled`` does that where
    evenly spaced frames are wanted.

    Parameters
    ----------
    path : path-like
    fps : float, optional
        The rate of each clip's frames (``clip.rotations``, ``clip.translations``: what foot
        planting and motion graphs read); sampling follows the keys whatever it is. Default each
        clip's own: glTF its key rate (the inverse of the median interval between keys), BVH
        its frame rate.
    allow_outside : bool
        Let a glTF file's external buffers lie outside its folder (see docs/security.md).
    up_axis, meters_per_unit : optional
        The skeleton's up axis ("x", "y", "z") and metres per unit, where the file's are wrong or
        missing.

    Returns
    -------
    dict of str to SkeletalClip
        By clip name; a glTF file with several distinct skins names them "skin/clip". The clips of
        one skin share one Skeleton: the skin's joints and, above them, the nodes that place the
        model (an armature's rotation and scale), parents before children.

    Raises
    ------
    FileNotFoundError, FileFormatError (a malformed or truncated file, naming it and where),
    ValidationError (no skin, no animation, an unknown suffix, a bad `fps`, frames larger than
    the memory budget).
    """
    path = Path(path)
    if fps is not None:
        fps = validate.number(fps, "read_clips: fps", minimum=0, strict=True)
    stated = _stated_axes(up_axis, meters_per_unit, "read_clips")
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        names, parents, offsets, frame_time, rotations, translations = bvh.read(path)
        skeleton = Skeleton(
            names=names,
            parents=parents,
            rest=Pose(rotations=np.tile([0.0, 0, 0, 1], (len(names), 1)), translations=offsets),
            **{"up_axis": bvh.UP_AXIS, "meters_per_unit": None, **stated},
        )
        # files round the frame time (.0083333 for 120 fps): the rate to 0.01 fps is what was meant
        rate = round(1.0 / frame_time, 2)
        clip = SkeletalClip(skeleton=skeleton, fps=rate, rotations=rotations, translations=translations, name=path.stem)
        return {path.stem: _framed(clip, fps, path)}
    if suffix not in (".gltf", ".glb"):
        raise ValidationError(
            f"{path}: read_clips reads .gltf, .glb and .bvh files; got {suffix or 'a file without a suffix'!r}"
        )
    skins = list(gltf.skin_clips(path, fps, allow_outside=allow_outside))
    found = {}
    for skin, names, parents, translations, rotations, scales, clips in skins:
        skeleton = Skeleton(
            names=names, parents=parents, rest=Pose(rotations=rotations, translations=translations), scales=scales,
            **{"up_axis": gltf.UP_AXIS, "meters_per_unit": gltf.METERS_PER_UNIT, **stated},
        )  # fmt: skip
        for name, (rate, channels) in clips.items():
            key = f"{skin}/{name}" if len(skins) > 1 else name
            found[key] = SkeletalClip(skeleton=skeleton, fps=rate, channels=channels, name=key)
    if not found:
        raise ValidationError(f"{path}: no animation moves a skin's joints")
    return found


def _framed(clip: SkeletalClip, fps: float | None, source) -> SkeletalClip:
    """`clip` (frames) with its frames at `fps` instead, its keys kept: a clip of one channel per
    joint and path on the old frames' times."""
    if fps is None or fps == clip.fps:
        return clip
    validate.allocation((clip.duration * fps + 2) * clip.skeleton.n_joints * 7 * 2,
                        f"{source}: clip {clip.name!r} ({clip.duration:g} s) with frames at {fps:g} fps")  # fmt: skip
    times = clip.key_times
    channels = [Channel(joint=j, path=path, times=times, values=values[:, j])
                for j in range(clip.skeleton.n_joints)
                for path, values in (("rotation", clip.rotations), ("translation", clip.translations))]  # fmt: skip
    return SkeletalClip(skeleton=clip.skeleton, fps=fps, channels=channels, events=clip.events, name=clip.name)


EXPORT_SUFFIXES = (".csv", ".json", ".usda", ".usdc", ".glb", ".gltf")


def export(motion: Motion, path, **options) -> Path:
    """Write `motion` in the format its suffix names: .csv (long format: frame, agent, x, y[, z],
    readable by :func:`read_long`), .json, .glb / .gltf (glTF 2.0, for game engines and the web),
    or .usda / .usdc (Universal Scene Description, needs the ``usd`` extra; `options` ``fps`` and
    ``meters_per_unit`` as for :func:`write_usd`).
    Atomic: an interrupted export leaves nothing behind."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"export needs a flockkit.Motion; got {type(motion).__name__}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in EXPORT_SUFFIXES:
        raise ValidationError(
            f"{path}: unknown export extension {path.suffix!r}; expected {', '.join(EXPORT_SUFFIXES)}"
        )
    if suffix in (".csv", ".json", ".glb", ".gltf"):
        if options:
            raise ValidationError(f"{path}: options {', '.join(options)} are for USD exports")
        {".csv": write_csv, ".json": write_json}.get(suffix, write_gltf)(motion, path)
    else:
        write_usd(motion, path, **options)
    return path
