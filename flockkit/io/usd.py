"""USD (Universal Scene Description), through usd-core: the one module that imports pxr.

Writes, each on a stage with the conventions tools import unchanged (up axis z, metersPerUnit,
a time line at a frame rate Blender, Houdini and Maya play at the right speed), saved atomically:
a motion's agents as a PointInstancer (:func:`write_usd`), animated meshes and point clouds
(:func:`write_meshes`, for scenes), and crowds of skinned characters (:func:`write_crowd`). Frame
f is time code f * dt * fps, an integer wherever the frame rate is the time line's. Reads the
time-sampled ``UsdGeom.Mesh`` points of a stage (:func:`read_meshes`), after checking that every
layer it composes lies inside its folder.
"""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path

import numpy as np

from .. import _files, rigid, validate
from .._atomic import atomic_path
from ..errors import FileFormatError, MissingDependencyError, ValidationError
from ..mesh import fan_triangles
from ..motion import Motion

__all__ = ["USD_FPS", "write_usd", "write_meshes", "write_crowd", "read_meshes", "stage_axes", "time_range",
           "time_codes", "require_usd_core"]  # fmt: skip


# The frame rate of the time line a USD export is written on, unless asked otherwise: 24, the
# default scene rate of Blender, Houdini and Maya. Blender ignores a stage's framesPerSecond and
# reads its time codes as its own frames, so a time line at the rate the scene has is what plays
# at the right speed there; every USD reader that honours timeCodesPerSecond agrees.
USD_FPS = 24.0


def write_usd(motion: Motion, path, *, fps: float | None = USD_FPS, meters_per_unit: float = 1.0) -> None:
    """A USD stage (.usda text or .usdc binary) holding /Flock/Agents, a UsdGeom.PointInstancer
    with, per frame of the motion, a time sample of positions, orientations (facing the velocity,
    the prototype's +x), velocities and angular velocities; fixed ``ids`` (the agent indices), so
    identity never rests on point order.

    The stage's time line runs at `fps` (timeCodesPerSecond = framesPerSecond = fps; None: one
    time code per frame, fps = 1 / dt), each frame sampled at its time, t * fps; USD interpolates
    between samples. metersPerUnit is `meters_per_unit` (flockkit's units are meters by default),
    the up axis z; a 2D motion lies in the ground plane z = 0. Blender, Houdini and Maya import it
    at the right size and speed."""
    Gf, Usd, UsdGeom, Vt = _modules()
    positions = np.zeros((motion.n_frames, motion.n_agents, 3))
    positions[..., : motion.dims] = motion.positions
    velocities = np.zeros_like(positions)
    velocities[..., : motion.dims] = motion.velocities()
    quaternions = rigid.facing(velocities.reshape(-1, 3)).reshape(motion.n_frames, motion.n_agents, 4)
    turning = _angular_velocities(velocities, motion.dt)
    with _stage(path, "/Flock", dt=motion.dt, n_frames=motion.n_frames, fps=fps,
                   meters_per_unit=meters_per_unit) as (stage, times):  # fmt: skip
        instancer = UsdGeom.PointInstancer.Define(stage, "/Flock/Agents")
        body = UsdGeom.Cone.Define(stage, "/Flock/Agents/Prototypes/Agent")
        body.CreateAxisAttr(UsdGeom.Tokens.x)
        body.CreateHeightAttr(0.5)
        body.CreateRadiusAttr(0.15)
        instancer.CreatePrototypesRel().SetTargets([body.GetPath()])
        instancer.CreateProtoIndicesAttr(Vt.IntArray([0] * motion.n_agents))
        instancer.CreateIdsAttr(Vt.Int64Array(list(range(motion.n_agents))))
        points, turns = instancer.CreatePositionsAttr(), instancer.CreateOrientationsAttr()
        speeds, spins = instancer.CreateVelocitiesAttr(), instancer.CreateAngularVelocitiesAttr()
        for frame, when in enumerate(times):
            time = Usd.TimeCode(float(when))
            points.Set(Vt.Vec3fArray.FromNumpy(positions[frame].astype(np.float32)), time)
            speeds.Set(Vt.Vec3fArray.FromNumpy(velocities[frame].astype(np.float32)), time)
            spins.Set(Vt.Vec3fArray.FromNumpy(turning[frame].astype(np.float32)), time)
            turns.Set(
                Vt.QuathArray(
                    [Gf.Quath(float(w), Gf.Vec3h(float(x), float(y), float(z))) for w, x, y, z in quaternions[frame]]
                ),
                time,
            )


def write_meshes(path, objects, *, dt: float, n_frames: int, fps: float | None = USD_FPS,
                 meters_per_unit: float = 1.0, metadata: dict | None = None) -> None:  # fmt: skip
    """A USD stage of objects under /Scene, each (name, positions (T, N, D), faces (F, K) or None,
    custom data {key: value}[, transform]): an animated UsdGeom.Mesh where it has faces, else
    UsdGeom.Points, its points time-sampled at each of the `n_frames` frames `dt` apart (a 2D
    object lies in z = 0). An object with a `transform`, (translations (T, 3), turns (T,) radians
    about +z, unwrapped), holds its points in its own frame and is placed by time-sampled
    translate and rotateZ ops (degrees; unwrapped, so that readers interpolate the short way).
    The stage as :func:`write_usd` makes it, `metadata` (JSON-like) in its root layer's
    ``customLayerData["flockkit"]``."""
    _, Usd, UsdGeom, Vt = _modules()
    with _stage(path, "/Scene", dt=dt, n_frames=n_frames, fps=fps, meters_per_unit=meters_per_unit,
                metadata=metadata) as (stage, times):  # fmt: skip
        for name, motion_positions, faces, custom, *transform in objects:
            prim = UsdGeom.Mesh.Define(stage, name) if faces is not None else UsdGeom.Points.Define(stage, name)
            if faces is not None:
                faces = np.asarray(faces)
                prim.CreateFaceVertexCountsAttr(Vt.IntArray([faces.shape[1]] * len(faces)))
                prim.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.ravel().tolist()))
            else:
                prim.CreateWidthsAttr(Vt.FloatArray([0.05]))
            points = prim.CreatePointsAttr()
            positions = np.zeros((*motion_positions.shape[:2], 3), dtype=np.float32)
            positions[..., : motion_positions.shape[2]] = motion_positions
            for frame, when in enumerate(times):
                points.Set(Vt.Vec3fArray.FromNumpy(positions[frame]), Usd.TimeCode(float(when)))
            for key, value in custom.items():
                prim.GetPrim().SetCustomDataByKey(key, value)
            if transform:
                translations, turns = (np.asarray(a, dtype=float) for a in transform[0])
                translate, rotate = prim.AddTranslateOp(), prim.AddRotateZOp()
                for frame, when in enumerate(times):
                    translate.Set(tuple(float(x) for x in translations[frame]), Usd.TimeCode(float(when)))
                    rotate.Set(float(np.degrees(turns[frame])), Usd.TimeCode(float(when)))


def write_crowd(path, *, names, joints, rest, bind, scales, fps: float, n_frames: int, rotations, translations,
                library=(), references=None, samples=None, roots=None, mesh=None, instanceable: bool = False,
                meters_per_unit: float = 1.0, metadata: dict | None = None) -> None:  # fmt: skip
    """A USD crowd under /Crowd, written as UsdSkel lays a crowd out (one Sdf layer, saved atomically).

    Every pose the file holds is a row of the pose table `rotations` (M, J, 4; x, y, z, w) and
    `translations` (M, J, 3), float32. /CrowdPrototypes (a class: abstract, drawn by no one)
    holds the character once: ``Skeleton`` (`joints` as UsdSkel paths, `bind` model-space and
    `rest` local transforms (J, 4, 4), column vectors), ``Body`` (where `mesh` is given: a Mesh
    of ``points`` (V, 3), ``faces`` (F, 3), ``joint_indices`` / ``joint_weights`` (V, K), optional
    ``normals``, bound to the skeleton's joints in its order with an identity geomBindTransform),
    and one SkelAnimation per entry of `library`, (name, first, rows): time code first + i holds
    table row rows[i].

    Each agent k is /Crowd/<names[k]>, a SkelRoot bound to its own Skeleton (a reference to the
    prototype's) whose animation source is its SkelAnimation ``Skeleton/Animation``: either a
    reference to library entry ``references[k] = (entry, offset, scale)`` with that layer offset
    (agent time t reads the entry at (t - offset) / scale: one stream at one offset, or dilating at
    one rate), or time samples ``samples[k]`` (n_frames,) table rows, one per frame. Each distinct
    row is one Vt array, and usdc stores an array once however many samples hold it, so agents
    that read shared streams frame by frame cost an index per sample. Its ``Body`` references the
    prototype's (one copy of the mesh in the file), instanceable where `instanceable` (readers that
    skin instance proxies share it in memory too; Blender 5.0 then imports it undeformed). `roots`
    (translations (F, N, 3), orientations (F, N, 4) x, y, z, w, uniform scales (F, N)) place each
    agent by translate, rotateZ (where it only turns about z) and orient, and scale ops, each a
    default value where it never changes, else a time sample per frame.

    Frame f is time code f (integers, frame 0 at 0): startTimeCode 0, endTimeCode n_frames - 1,
    timeCodesPerSecond = framesPerSecond = `fps`; up axis z, metersPerUnit `meters_per_unit`,
    `metadata` in ``customLayerData["flockkit"]``."""
    Gf, _, _, Vt = _modules()
    from pxr import Sdf

    fps = validate.number(fps, "USD fps", minimum=0, strict=True)
    rotations = np.ascontiguousarray(rotations, dtype=np.float32)
    translations = np.ascontiguousarray(translations, dtype=np.float32)
    references, samples = dict(references or {}), dict(samples or {})
    table: dict = {}

    def row(k: int):
        """Row k of the pose table as Vt arrays, made once: usdc then stores them once."""
        found = table.get(k)
        if found is None:
            found = table[k] = (Vt.QuatfArray.FromNumpy(rotations[k]), Vt.Vec3fArray.FromNumpy(translations[k]))
        return found

    matrices = lambda m: Vt.Matrix4dArray([Gf.Matrix4d(x.T.tolist()) for x in np.asarray(m)])  # noqa: E731
    token_joints = Vt.TokenArray(list(joints))
    half_scales = Vt.Vec3hArray.FromNumpy(np.asarray(scales).astype(np.float16))
    with _layer(path, "Crowd", n_frames=n_frames, fps=fps, meters_per_unit=meters_per_unit,
                metadata=metadata) as (layer, crowd):  # fmt: skip
        prototypes = Sdf.PrimSpec(layer, "CrowdPrototypes", Sdf.SpecifierClass)
        skeleton = Sdf.PrimSpec(prototypes, "Skeleton", Sdf.SpecifierDef, "Skeleton")
        _attribute(skeleton, "joints", Sdf.ValueTypeNames.TokenArray, token_joints, uniform=True)
        _attribute(skeleton, "bindTransforms", Sdf.ValueTypeNames.Matrix4dArray, matrices(bind), uniform=True)
        _attribute(skeleton, "restTransforms", Sdf.ValueTypeNames.Matrix4dArray, matrices(rest), uniform=True)
        _relationship(skeleton, "skel:animationSource", skeleton.path.AppendChild("Animation"))
        _api(skeleton, "SkelBindingAPI")
        body = None
        if mesh is not None:
            body = Sdf.PrimSpec(prototypes, "Body", Sdf.SpecifierDef, "Xform")
            _mesh(Sdf.PrimSpec(body, "Mesh", Sdf.SpecifierDef, "Mesh"), mesh, token_joints, Sdf, Gf, Vt)
        streams = Sdf.PrimSpec(prototypes, "Streams", Sdf.SpecifierDef, "Scope")
        entries = []
        for name, first, rows in library:
            animation = Sdf.PrimSpec(streams, name, Sdf.SpecifierDef, "SkelAnimation")
            _animation(animation, token_joints, half_scales, enumerate(np.asarray(rows).tolist(), first), row, Sdf)
            entries.append(animation.path)
        placements = _placements(*roots) if roots is not None else None
        for k, name in enumerate(names):
            agent = Sdf.PrimSpec(crowd, name, Sdf.SpecifierDef, "SkelRoot")
            bones = Sdf.PrimSpec(agent, "Skeleton", Sdf.SpecifierDef, "Skeleton")
            bones.referenceList.Prepend(Sdf.Reference(primPath=skeleton.path))
            _api(agent, "SkelBindingAPI")
            _relationship(agent, "skel:skeleton", bones.path)
            animation = Sdf.PrimSpec(bones, "Animation", Sdf.SpecifierDef, "SkelAnimation")
            if k in references:
                entry, offset, scale = references[k]
                animation.referenceList.Prepend(
                    Sdf.Reference(primPath=entries[entry], layerOffset=Sdf.LayerOffset(float(offset), float(scale)))
                )
            else:
                frames = np.asarray(samples[k])
                if frames.shape != (n_frames,):
                    raise ValidationError(f"write_crowd: agent {name} has {frames.shape} sample rows; needs {n_frames}")
                _animation(animation, token_joints, half_scales, enumerate(frames.tolist()), row, Sdf)
            if body is not None:
                part = Sdf.PrimSpec(agent, "Body", Sdf.SpecifierDef, "Xform")
                part.referenceList.Prepend(Sdf.Reference(primPath=body.path))
                part.SetInfo("instanceable", bool(instanceable))
            if placements is not None:
                _place(agent, next(placements), Sdf, Gf, Vt)


def _attribute(prim, name: str, type_name, value=None, *, uniform: bool = False, samples=None):
    """An attribute spec on `prim`: its default `value` and/or time `samples` ((time, value) pairs)."""
    from pxr import Sdf

    variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
    spec = Sdf.AttributeSpec(prim, name, type_name, variability)
    if value is not None:
        spec.default = value
    for time, sample in samples or ():
        spec.SetTimeSample(float(time), sample)
    return spec


def _relationship(prim, name: str, target) -> None:
    from pxr import Sdf

    Sdf.RelationshipSpec(prim, name, custom=False).targetPathList.explicitItems = [target]


def _api(prim, *schemas: str) -> None:
    from pxr import Sdf

    prim.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=list(schemas)))


def _animation(prim, joints, scales, rows, row, Sdf) -> None:
    """A SkelAnimation's joints, fixed scales and, per (time code, table row), its rotations and translations."""
    _attribute(prim, "joints", Sdf.ValueTypeNames.TokenArray, joints, uniform=True)
    _attribute(prim, "scales", Sdf.ValueTypeNames.Half3Array, scales)
    turns = _attribute(prim, "rotations", Sdf.ValueTypeNames.QuatfArray)
    moves = _attribute(prim, "translations", Sdf.ValueTypeNames.Float3Array)
    for time, k in rows:
        rotation, translation = row(k)
        turns.SetTimeSample(float(time), rotation)
        moves.SetTimeSample(float(time), translation)


def _mesh(prim, mesh: dict, joints, Sdf, Gf, Vt) -> None:
    """A polygon mesh (no subdivision) skinned by the skeleton's joints in its order."""
    faces = np.asarray(mesh["faces"], dtype=np.int32)
    indices = np.asarray(mesh["joint_indices"], dtype=np.int32)
    types = Sdf.ValueTypeNames
    _attribute(prim, "points", types.Point3fArray, Vt.Vec3fArray.FromNumpy(np.asarray(mesh["points"], np.float32)))
    _attribute(prim, "faceVertexCounts", types.IntArray, Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    _attribute(prim, "faceVertexIndices", types.IntArray, Vt.IntArray.FromNumpy(faces.ravel()))
    _attribute(prim, "subdivisionScheme", types.Token, "none", uniform=True)
    extent = np.stack([np.min(mesh["points"], axis=0), np.max(mesh["points"], axis=0)]).astype(np.float32)
    _attribute(prim, "extent", types.Float3Array, Vt.Vec3fArray.FromNumpy(extent))
    if mesh.get("normals") is not None:
        normals = _attribute(prim, "normals", types.Normal3fArray,
                             Vt.Vec3fArray.FromNumpy(np.asarray(mesh["normals"], np.float32)))  # fmt: skip
        normals.SetInfo("interpolation", "vertex")
    for name, type_name, values in (
        ("primvars:skel:jointIndices", types.IntArray, Vt.IntArray.FromNumpy(indices.ravel())),
        ("primvars:skel:jointWeights", types.FloatArray,
         Vt.FloatArray.FromNumpy(np.asarray(mesh["joint_weights"], np.float32).ravel())),
    ):  # fmt: skip
        spec = _attribute(prim, name, type_name, values)
        spec.SetInfo("interpolation", "vertex")
        spec.SetInfo("elementSize", int(indices.shape[1]))
    _attribute(prim, "primvars:skel:geomBindTransform", types.Matrix4d, Gf.Matrix4d(1))
    _attribute(prim, "skel:joints", types.TokenArray, joints, uniform=True)
    _api(prim, "SkelBindingAPI")


def _placements(moves, turns, sizes):
    """Per agent, its xform ops as (name, type, values (F, ...)) from translations (F, N, 3),
    unit quaternions (F, N, 4) x, y, z, w and uniform scales (F, N): translate; where an agent
    only turns about z from its first orientation (as a Driver turns a character to its heading),
    rotateZ (degrees, unwrapped, so that USD interpolates the short way) and a fixed orient, else
    orient per frame; scale. A float per frame costs a third of a quaternion in a .usdc."""
    from scipy.spatial.transform import Rotation

    moves = np.asarray(moves, np.float32)
    turns = np.asarray(turns, np.float64)
    frames, agents = turns.shape[:2]
    first = Rotation.from_quat(np.broadcast_to(turns[:1], turns.shape).reshape(-1, 4))
    relative = (Rotation.from_quat(turns.reshape(-1, 4)) * first.inv()).as_rotvec().reshape(frames, agents, 3)
    about_z = np.all(np.abs(relative[..., :2]) <= 1e-7, axis=(0, 2))
    yaw = np.degrees(np.unwrap(relative[..., 2], axis=0)).astype(np.float32)
    scales = np.repeat(np.asarray(sizes, np.float32)[..., None], 3, axis=2)
    for k in range(agents):
        ops = [("xformOp:translate", "Float3", moves[:, k])]
        if about_z[k]:
            ops += [("xformOp:rotateZ", "Float", yaw[:, k]), ("xformOp:orient", "Quatf", turns[:1, k])]
        else:
            ops.append(("xformOp:orient", "Quatf", turns[:, k]))
        ops.append(("xformOp:scale", "Float3", scales[:, k]))
        yield ops


def _place(prim, ops, Sdf, Gf, Vt) -> None:
    """The xform ops `ops` on `prim`: a default value where a value never changes, else a time
    sample per frame (values read out of one Vt array: no Python object per number)."""
    arrays = {"Float3": Vt.Vec3fArray, "Quatf": Vt.QuatfArray}
    for name, type_name, values in ops:
        if type_name == "Float":
            values = values.tolist()
        else:
            values = arrays[type_name].FromNumpy(np.ascontiguousarray(values, dtype=np.float32))
        if all(v == values[0] for v in values):
            _attribute(prim, name, getattr(Sdf.ValueTypeNames, type_name), values[0])
        else:
            _attribute(prim, name, getattr(Sdf.ValueTypeNames, type_name), samples=enumerate(values))
    _attribute(prim, "xformOpOrder", Sdf.ValueTypeNames.TokenArray, [name for name, _, _ in ops], uniform=True)


def require_usd_core() -> None:
    """Nothing, where usd-core is installed; MissingDependencyError naming the extra where it is
    not (what a command checks before a long run that ends in a USD export)."""
    _modules()


def _modules():
    """pxr's (Gf, Usd, UsdGeom, Vt); MissingDependencyError naming the extra when usd-core is absent."""
    try:
        from pxr import Gf, Usd, UsdGeom, Vt
    except ImportError:
        raise MissingDependencyError("USD export needs usd-core: pip install 'flockkit[usd]'") from None
    return Gf, Usd, UsdGeom, Vt


@contextlib.contextmanager
def _stage(path, root: str, *, dt: float, n_frames: int, fps: float | None = USD_FPS, meters_per_unit: float = 1.0,
           metadata: dict | None = None):  # fmt: skip
    """A new USD stage, saved atomically to `path` on leaving: up axis z, metersPerUnit
    `meters_per_unit`, a time line at `fps` (timeCodesPerSecond = framesPerSecond; None: 1 / dt)
    over `n_frames` frames `dt` apart, an Xform `root` as its default prim, and `metadata` (what
    flockkit did to the coordinates: plain strings, numbers, lists and dicts) as the root layer's
    ``customLayerData["flockkit"]``. Yields (stage, the time code of each frame)."""
    _, Usd, UsdGeom, _ = _modules()
    fps = 1.0 / dt if fps is None else validate.number(fps, "USD fps", minimum=0, strict=True)
    meters_per_unit = validate.number(meters_per_unit, "USD meters_per_unit", minimum=0, strict=True)
    times = time_codes(n_frames, dt, fps)
    with atomic_path(Path(path), create=False) as tmp:  # USD creates the layer itself
        stage = Usd.Stage.CreateNew(str(tmp))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
        stage.SetTimeCodesPerSecond(fps)
        stage.SetFramesPerSecond(fps)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(float(times[-1]))
        stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, root).GetPrim())
        if metadata:
            stage.GetRootLayer().customLayerData = {"flockkit": _plain(metadata)}
        yield stage, times
        stage.GetRootLayer().Save()


def time_codes(n_frames: int, dt: float, fps: float) -> np.ndarray:
    """The time code of each of `n_frames` frames `dt` seconds apart on a time line at `fps`:
    frame f at f * dt * fps, frame 0 at 0. Where that is an integer up to rounding (the frame rate
    is the time line's, or a multiple), the integer itself: 239, not 238.99999999999997 (a reader
    comparing time codes with frames, as Blender does, would miss the last frame)."""
    times = np.arange(n_frames) * (dt * fps)
    whole = np.round(times)
    return np.where(np.abs(times - whole) <= 1e-6 * np.maximum(1.0, np.abs(whole)), whole, times)


@contextlib.contextmanager
def _layer(path, root: str, *, n_frames: int, fps: float, meters_per_unit: float = 1.0, metadata: dict | None = None):
    """A new Sdf layer (what :func:`_stage` makes, authored without a stage: no recomposition while
    tens of thousands of prims are written), saved atomically to `path` on leaving: up axis z,
    metersPerUnit, frames 0 .. n_frames - 1 at `fps`, an Xform `root` as its default prim.
    Yields (layer, the root's prim spec)."""
    from pxr import Sdf

    meters_per_unit = validate.number(meters_per_unit, "USD meters_per_unit", minimum=0, strict=True)
    with atomic_path(Path(path), create=False) as tmp:
        layer = Sdf.Layer.CreateNew(str(tmp))
        with Sdf.ChangeBlock():
            layer.pseudoRoot.SetInfo("upAxis", "Z")
            layer.pseudoRoot.SetInfo("metersPerUnit", float(meters_per_unit))
            layer.timeCodesPerSecond = layer.framesPerSecond = float(fps)
            layer.startTimeCode, layer.endTimeCode = 0.0, float(max(n_frames - 1, 0))
            layer.defaultPrim = root
            if metadata:
                layer.customLayerData = {"flockkit": _plain(metadata)}
            spec = Sdf.PrimSpec(layer, root, Sdf.SpecifierDef, "Xform")
            yield layer, spec
        layer.Save()


def _plain(value):
    """`value` (dicts of strings, numbers, flat lists of numbers or of strings, None) as USD
    dictionary values: None left out (USD has no null), a list of numbers a double array (row
    by row for a matrix), a list of strings a string array."""
    _, _, _, Vt = _modules()
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple | np.ndarray):
        if all(isinstance(v, str) for v in value):
            return Vt.StringArray(list(value))
        return Vt.DoubleArray(np.asarray(value, dtype=np.float64).ravel().tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def _angular_velocities(velocities: np.ndarray, dt: float) -> np.ndarray:
    """Degrees per second (USD's unit) about the axis turning each agent's heading at frame t
    onto its heading at t + 1 (zero at the last frame and for agents at rest), shape (T, N, 3)."""
    speed = np.linalg.norm(velocities, axis=2, keepdims=True)
    heading = np.divide(velocities, speed, out=np.zeros_like(velocities), where=speed > 1e-12)
    turning = np.zeros_like(velocities)
    axis = np.cross(heading[:-1], heading[1:])
    sine = np.linalg.norm(axis, axis=2, keepdims=True)
    angle = np.arctan2(sine, np.sum(heading[:-1] * heading[1:], axis=2, keepdims=True))
    unit = np.divide(axis, sine, out=np.zeros_like(axis), where=sine > 1e-12)
    turning[:-1] = unit * np.degrees(angle) / dt
    return turning


def _open(path, allow_outside: bool = False):
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


def read_meshes(path, fps: float, *, allow_outside: bool = False) -> tuple[np.ndarray, np.ndarray, str, float]:
    """(positions (T, V, 3), faces (F, 3), up axis, metres per unit) of every ``UsdGeom.Mesh`` of
    the stage at `path`, in world space, sampled at `fps` over the stage's time range (polygons
    split into fans), with the stage's axes (:func:`stage_axes`)."""
    from pxr import Usd, UsdGeom

    path = Path(path)
    stage = _open(path, allow_outside)
    up_axis, meters_per_unit = stage_axes(stage, path)
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
    return np.concatenate(positions, axis=1), np.concatenate(faces), up_axis, meters_per_unit


def stage_axes(stage, path) -> tuple[str, float]:
    """(up axis "y" or "z", metres per unit) of an open stage: its upAxis and metersPerUnit
    metadata, or where it has none USD's fallbacks (UsdGeom: y up unless the installation says
    otherwise, and 0.01, centimetres). FileFormatError naming the file and the field for a value
    USD does not allow (an axis other than Y or Z, a unit that is not a finite number above 0)."""
    from pxr import UsdGeom

    up = stage.GetMetadata("upAxis") if stage.HasAuthoredMetadata("upAxis") else UsdGeom.GetFallbackUpAxis()
    if str(up) not in (UsdGeom.Tokens.y, UsdGeom.Tokens.z):
        raise FileFormatError(f"{path}: upAxis must be Y or Z (UsdGeom); got {str(up)[:40]!r}")
    unit = UsdGeom.GetStageMetersPerUnit(stage)
    if isinstance(unit, bool) or not isinstance(unit, int | float) or not math.isfinite(unit) or unit <= 0:
        raise FileFormatError(f"{path}: metersPerUnit must be a finite number above 0; got {str(unit)[:40]!r}")
    return str(up).lower(), float(unit)


def time_range(path, *, allow_outside: bool = False) -> float:
    """Seconds from the start of the stage at `path` to its end."""
    stage = _open(path, allow_outside)
    return (stage.GetEndTimeCode() - stage.GetStartTimeCode()) / stage.GetTimeCodesPerSecond()
