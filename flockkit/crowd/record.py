"""A crowd run kept frame by frame, and its exports for animation tools and engines.

``export_usd`` runs a crowd and writes it as UsdSkel lays out a crowd: the character's skeleton
and skinned mesh once, one SkelAnimation per stream run that agents reference at their own time
offsets, and per-agent time samples only for agents whose motion is not one stream at one offset
(see its docstring for what is exact). ``CrowdRecording.export_usd`` writes a recording, every
agent's poses as time samples that share every pose they repeat. ``export_gltf`` writes a crowd
as one .glb of skinned characters that engines load.
"""

from __future__ import annotations

import attrs
import numpy as np

from .. import rigid, validate
from ..errors import ValidationError
from ..skeleton import Skeleton

__all__ = ["CrowdRecording", "record", "write_engine_buffers"]


@attrs.frozen(kw_only=True, eq=False)
class CrowdRecording:
    """Frames of a crowd: `roots` (F, N, 4, 4) world transforms of each agent's root (identity
    for a crowd not driven by trajectories), `rotations` (F, N, J, 4) and `translations`
    (F, N, J, 3) the local joint poses of `cluster` (float32, as the store holds them), the
    `streams` (F, N) each agent reads or blends to (unique slots as 1000 + slot), whether it is
    `blending` (F, N), at `fps`; `axes` how the character was placed in the world, when driven
    (``Driver.axes``: its up and forward axes and metres per unit, which the roots include),
    recorded in exports."""

    skeleton: Skeleton
    fps: float
    cluster: str
    roots: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    streams: np.ndarray
    blending: np.ndarray
    axes: dict = attrs.field(factory=dict)

    @property
    def n_frames(self) -> int:
        return len(self.roots)

    @property
    def n_agents(self) -> int:
        return self.roots.shape[1]

    def world(self) -> np.ndarray:
        """World joint matrices (F, N, J, 4, 4): each agent's root times its pose's forward kinematics."""
        from ..skeleton import Pose

        local = self.skeleton.world(
            Pose._adopt(self.rotations.astype(np.float64), self.translations.astype(np.float64))
        )
        return self.roots[:, :, None] @ local

    def export_usd(self, path, *, mesh=None, meters_per_unit: float = 1.0, instanceable: bool = False) -> None:
        """A USD stage (.usda/.usdc) of the recording, laid out as ``flockkit.crowd.export_usd``
        lays a crowd out (see there: /Crowd/Agent_k a UsdSkel.Root placed by the agent's root at
        each frame, its Skeleton and SkelAnimation, the skinned `mesh` (a ``SkinnedMesh`` from
        ``read_skin``, optional) bound to it), every agent's local joint rotations and
        translations as a time sample per frame; a pose that recurs (agents reading one stream
        frame) is stored once. Frame f at time code f, frames per second the recording's; up axis
        z, `meters_per_unit`; saved atomically. The roots place each character upright along +z
        at its true size (``Driver`` turns its up axis onto +z and scales it by its metres per
        unit), and the stage's ``customLayerData["flockkit"]`` records that conversion (`axes`).
        usd-core (extra ``usd``) is needed."""
        frames, agents, joints = self.rotations.shape[:3]
        rotations = np.ascontiguousarray(self.rotations, dtype=np.float32).reshape(frames * agents, joints * 4)
        translations = np.ascontiguousarray(self.translations, dtype=np.float32).reshape(frames * agents, joints * 3)
        both = np.ascontiguousarray(np.concatenate([rotations.view(np.uint32), translations.view(np.uint32)], axis=1))
        keys = both.view(np.dtype((np.void, both.shape[1] * 4))).ravel()
        _, first, rows = np.unique(keys, return_index=True, return_inverse=True)
        rows = rows.reshape(frames, agents)
        _write(path, self.skeleton, mesh, fps=self.fps, names=[f"Agent_{k}" for k in range(agents)],
               rotations=rotations[first].reshape(-1, joints, 4),
               translations=translations[first].reshape(-1, joints, 3),
               samples={k: rows[:, k] for k in range(agents)},
               roots=_similarities(self.roots, "CrowdRecording.roots"), axes=self.axes,
               meters_per_unit=meters_per_unit, instanceable=instanceable)  # fmt: skip


def _similarities(matrices, field: str):
    """(translations (..., 3), unit quaternions (..., 4) x, y, z, w, uniform scales (...)) of
    transforms (..., 4, 4) that rotate and scale alike along every axis, as a Driver's roots do;
    a ValidationError naming `field` for any other."""
    from scipy.spatial.transform import Rotation

    matrices = np.asarray(matrices, dtype=np.float64)
    linear = matrices[..., :3, :3]
    scale = np.cbrt(np.linalg.det(linear))
    rotation = linear / np.where(scale == 0, 1.0, scale)[..., None, None]
    off = np.abs(rotation @ np.swapaxes(rotation, -1, -2) - np.eye(3)).max() if matrices.size else 0.0
    if np.any(scale == 0) or off > 1e-6 or np.abs(matrices[..., 3, :] - [0, 0, 0, 1]).max(initial=0) > 0:
        raise ValidationError(f"{field} must be rotations with a uniform scale and a translation, as a Driver's roots "
                              "are; USD places each agent by translate, orient and scale")  # fmt: skip
    quaternions = Rotation.from_matrix(rotation.reshape(-1, 3, 3)).as_quat().reshape(*scale.shape, 4)
    return matrices[..., :3, 3], quaternions, scale


def _write(
    path,
    skeleton: Skeleton,
    mesh,
    *,
    fps,
    names,
    rotations,
    translations,
    library=(),
    references=None,
    samples=None,
    roots=None,
    axes=None,
    meters_per_unit=1.0,
    instanceable=False,
    n_frames=None,
) -> None:
    """`write_crowd` of a skeleton's character (its skinned `mesh` bound where given)."""
    from ..io.skin import SkinnedMesh
    from ..io.usd import write_crowd

    bind = skeleton.world(skeleton.rest)  # model-space rest: the bind transforms without a mesh
    shape = None
    if mesh is not None:
        if not isinstance(mesh, SkinnedMesh):
            raise ValidationError(f"export_usd: mesh must be a flockkit.crowd.SkinnedMesh (read_skin); "
                                  f"got {type(mesh).__name__}")  # fmt: skip
        mesh.check_skeleton(skeleton, field="export_usd: mesh")
        bind = np.linalg.inv(mesh.inverse_bind)
        shape = {"points": mesh.positions, "faces": mesh.faces, "joint_indices": mesh.joints,
                 "joint_weights": mesh.weights, "normals": mesh.normals}  # fmt: skip
    if n_frames is None:
        n_frames = len(next(iter(samples.values()))) if samples else 1
    write_crowd(
        path,
        names=names,
        joints=_joint_paths(skeleton),
        rest=rigid.trs(skeleton.rest.translations, skeleton.rest.rotations, skeleton.scales),
        bind=bind,
        scales=skeleton.scales,
        fps=fps,
        n_frames=n_frames,
        rotations=rotations,
        translations=translations,
        library=library,
        references=references,
        samples=samples,
        roots=roots,
        mesh=shape,
        instanceable=instanceable,
        meters_per_unit=meters_per_unit,
        metadata={"character": dict(axes)} if axes else None,
    )


def _joint_paths(skeleton: Skeleton) -> list[str]:
    """UsdSkel joint paths ("hips/spine/head"): each name made a valid path element, under its parent's path."""
    import re

    names = [re.sub(r"[^A-Za-z0-9_]", "_", n) for n in skeleton.names]
    names = [n if n and not n[0].isdigit() else f"j_{n}" for n in names]
    paths: list[str] = []
    for j, parent in enumerate(skeleton.parents):
        paths.append(names[j] if parent < 0 else f"{paths[parent]}/{names[j]}")
    return paths


def _run(source, seconds, on_frame, what: str, *, initial: bool = False):
    """(crowd, driver or None, a generator that steps `source` frame by frame for `seconds`).

    By default each frame is made by ``on_frame(crowd, frame)`` then an update, and yielded after
    it (frame 0 is the state after the first update). With `initial`, frame 0 is the state
    before any update (crowd time 0, the trajectories' first frame) and frame f + 1 follows from
    ``on_frame(crowd, f)`` and one update, so that frame f is the crowd at time f / fps."""
    from .drive import Driver
    from .runtime import Crowd

    driver = source if isinstance(source, Driver) else None
    crowd = driver.crowd if driver is not None else source
    if not isinstance(crowd, Crowd):
        raise ValidationError(f"{what} needs a flockkit.Crowd or a crowd Driver; got {type(source).__name__}")
    seconds = validate.number(seconds, f"{what}: seconds", minimum=0, strict=True)
    count = int(round(seconds * crowd.pool.fps))
    if count < 1:
        raise ValidationError(f"{what}: seconds must reach at least one frame at {crowd.pool.fps:g} fps; got {seconds}")

    def step(frame):
        if on_frame is not None:
            on_frame(crowd, frame)
        if driver is not None:
            driver.step()
        else:
            crowd.update()

    def frames():
        for frame in range(count):
            if not initial:
                step(frame)
            yield frame
            if initial and frame + 1 < count:
                step(frame)

    return crowd, driver, frames()


def record(source, seconds: float, *, agents=None, cluster=None, on_frame=None) -> CrowdRecording:
    """Run `source` (a ``flockkit.Crowd``, or a ``flockkit.crowd.Driver`` that moves one) for
    `seconds` and keep round(seconds * fps) frames of the roots, local poses and streams of
    `agents` (default all) in `cluster` (default the driver's, or the crowd's first): frame 0 the
    crowd as it is (time 0: a driver's first trajectory frame), frame f + 1 after one more
    update. ``on_frame(crowd, frame)`` is called after frame `frame` is kept, before the update
    that makes the next (to start transitions); the last frame kept is the crowd's state when
    ``record`` returns."""
    crowd, driver, frames = _run(source, seconds, on_frame, "record", initial=True)
    if cluster is None:
        cluster = driver.cluster if driver is not None else crowd.clusters[0]
    c = crowd.cluster_index(cluster)
    ids = np.arange(crowd.n_agents) if agents is None else np.asarray(agents)
    roots, rotations, translations, streams, blending = [], [], [], [], []
    for _ in frames:
        pose = crowd.poses(ids, cluster)
        rotations.append(np.asarray(pose.rotations))
        translations.append(np.asarray(pose.translations))
        roots.append(driver.roots[ids].copy() if driver is not None else np.tile(np.eye(4), (len(ids), 1, 1)))
        entry = crowd.instance_buffer()[ids, c]
        moving = entry["blend_time"] > 0
        unique = np.where(moving, entry["target_kind"], entry["kind"]) == 2
        streams.append(np.where(moving, entry["target"], entry["stream"]) + np.where(unique, 1000, 0))
        blending.append(moving)
    return CrowdRecording(
        skeleton=crowd.skeletons[c],
        fps=crowd.pool.fps,
        cluster=cluster,
        roots=np.array(roots),
        rotations=np.array(rotations),
        translations=np.array(translations),
        streams=np.array(streams),
        blending=np.array(blending),
        axes=dict(driver.axes) if driver is not None else {},
    )


# A part dilating at one rate for a whole export reads its stream along a straight line of frames;
# its reference to the stream is taken when every frame lies within this many frames of the line
# (float32 offsets stepped by the rate drift about 1e-5 frames over a run), else it gets samples.
LINE_TOLERANCE = 1e-4


def export_usd(source, path, seconds: float, *, mesh=None, agents=None, cluster=None, on_frame=None,
               meters_per_unit: float = 1.0, instanceable: bool = False) -> dict:  # fmt: skip
    """Run `source` (a ``flockkit.Crowd`` or a ``flockkit.crowd.Driver``) for `seconds` and write
    `agents` (default all) of `cluster` (default the driver's, or the crowd's first) to the USD
    stage `path` (.usda/.usdc) as skinned characters that share their streams' animations.

    The layout (``flockkit.io.usd.write_crowd``): /CrowdPrototypes, a class beside /Crowd, holds the character
    once (the Skeleton; ``Body``, the skinned `mesh` from ``read_skin`` bound to its joints, where
    given) and ``Streams``, one SkelAnimation per run of each stream the agents read (a Stopped
    stream that starts again starts a new run), its time code j holding the stream's j-th frame
    since it (re)started. /Crowd/Agent_k is a SkelRoot placed by the agent's root (translate,
    orient, scale, per frame where a Driver moves it), binding its own Skeleton (a reference to
    the prototype's) to its SkelAnimation and skinning its ``Body`` (a reference to the
    prototype's; `instanceable` marks it instanceable, for readers that skin instance proxies,
    which Blender 5.0 does not). Frame f (the crowd at time f / fps; frame 0 the crowd before its
    first update) is time code f: startTimeCode 0, endTimeCode frames - 1, timeCodesPerSecond =
    framesPerSecond = the pool's fps. Up axis z, metresPerUnit `meters_per_unit`, and the
    driver's conversion of the character's axes in ``customLayerData["flockkit"]``.

    What each agent's SkelAnimation is, and what is exact:

    - An agent that reads one stream run during the whole export, without blending, at one offset
      or dilating at one rate, references that run's SkelAnimation with a layer offset (and, when
      dilating, a scale): agent time t reads the run at frame j0 + slope * t. At whole offsets
      this is the stored pose itself; between frames (dilation) USD interpolates the two frames
      as the crowd does (slerp, lerp), equal up to float32 rounding. A reference is taken only
      when every frame lies within LINE_TOLERANCE frames of that line.
    - Any other agent (switching streams, blending, reading a unique slot, dilation starting or
      ending during the export) gets a time sample per frame of its own SkelAnimation, holding
      ``Crowd.poses`` exactly; frames where it reads a stream at a whole offset are the stream's
      stored pose, which the file holds once (usdc stores a repeated array once), so such an
      agent costs an index per frame, and only blends, dilation and unique slots add poses.

    Scales are the skeleton's (half precision, as UsdSkel stores them); rotations and
    translations float32, as the pose store holds them. Returns counts: ``agents``, ``frames``,
    ``referencing`` (agents with a reference), ``sampled`` (agents with samples), ``streams`` (run
    animations written) and ``poses`` (distinct poses stored). ``on_frame(crowd, frame)`` is called
    after frame `frame`, before the update that makes the next (to start transitions). Written
    atomically; needs usd-core (extra ``usd``)."""
    from ..io.usd import require_usd_core

    require_usd_core()  # before the run, not after it
    crowd, driver, c, ids, capture, placed = _capture(source, seconds, agents, cluster, on_frame, "export_usd")
    plan = capture.plan()
    library, entry, taken = [], {}, {}
    for run in plan["used"]:
        start, stop, first, name = plan["runs"][run]
        name = _prim_name(name)
        taken[name] = taken.get(name, -1) + 1
        entry[run] = len(library)
        library.append((f"{name}_{taken[name]}", first, np.arange(start, stop)))
    references = {k: (entry[run], -j0 / slope, 1.0 / slope) for k, (run, j0, slope) in plan["references"].items()}
    _write(path, crowd.skeletons[c], mesh, fps=crowd.pool.fps, names=[f"Agent_{int(k)}" for k in ids],
           rotations=plan["rotations"], translations=plan["translations"], library=library,
           references=references, samples=plan["samples"], roots=placed, n_frames=capture.n_frames,
           axes=driver.axes if driver is not None else None, meters_per_unit=meters_per_unit,
           instanceable=instanceable)  # fmt: skip
    return {"agents": len(ids), "frames": capture.n_frames, "referencing": len(plan["references"]),
            "sampled": len(plan["samples"]), "streams": len(library),
            "poses": len(plan["rotations"])}  # fmt: skip


def export_gltf(source, path, seconds: float, *, mesh, agents=None, cluster=None, on_frame=None) -> dict:
    """Run `source` (a ``flockkit.Crowd`` or a ``flockkit.crowd.Driver``) for `seconds` and write
    `agents` (default all) of `cluster` as one binary glTF 2.0 file `path` (.glb) that engines,
    three.js and Blender load: the skinned `mesh` (``read_skin``) and its inverse bind matrices
    once; per agent a root node (``Agent_k``, placed by the driver's root: translation, rotation,
    scale, animated where they change) above its own joint nodes, a skin of them and a root node
    drawing the shared mesh with that skin; one animation, "crowd", keying every agent's joints
    (rotation, translation; LINEAR) and roots at every frame, frame f at f / fps seconds (frame 0
    the crowd before its first update).

    An agent that reads one stream at one whole offset for the whole export keys its joints with
    accessors into that stream's frames (stored once, joint by joint), starting at its offset:
    the stored poses themselves. Every other agent keys its own frames, ``Crowd.poses`` as they
    are. Between frames, engines slerp and lerp the keys (the crowd's own interpolation for a
    dilating part reads the same two frames). A file larger than
    ``flockkit.io.gltf_crowd.GLTF_CROWD_LIMIT`` (256 MiB) is refused with a ValidationError
    naming it, before anything is written; ``export_usd`` shares more (dilating agents too, and readers load
    references lazily). Returns counts: ``agents``, ``frames``, ``sharing`` (agents keyed by
    their stream's frames), ``own`` and ``bytes``. Written atomically."""
    from ..io.gltf_crowd import write_gltf_crowd
    from ..io.skin import SkinnedMesh

    if not isinstance(mesh, SkinnedMesh):
        raise ValidationError(f"export_gltf: mesh must be a flockkit.crowd.SkinnedMesh (read_skin); "
                              f"got {type(mesh).__name__}")  # fmt: skip
    crowd, driver, c, ids, capture, placed = _capture(source, seconds, agents, cluster, on_frame, "export_gltf",
                                                      mesh=mesh)  # fmt: skip
    plan = capture.plan(lines=False)
    skeleton = crowd.skeletons[c]
    windows = {k: (run, int(j0) - plan["runs"][run][2]) for k, (run, j0, _) in plan["references"].items()}
    shape = {"points": mesh.positions, "faces": mesh.faces, "joint_indices": mesh.joints,
             "joint_weights": mesh.weights, "normals": mesh.normals, "inverse_bind": mesh.inverse_bind,
             "name": mesh.name}  # fmt: skip
    size = write_gltf_crowd(path, names=[f"Agent_{int(k)}" for k in ids], joints=skeleton.names,
                            parents=skeleton.parents, rest_translations=skeleton.rest.translations,
                            rest_rotations=skeleton.rest.rotations, scales=skeleton.scales, mesh=shape,
                            fps=crowd.pool.fps, n_frames=capture.n_frames, rotations=plan["rotations"],
                            translations=plan["translations"], runs=[r[:2] for r in plan["runs"]], windows=windows,
                            samples=plan["samples"], roots=placed)  # fmt: skip
    return {"agents": len(ids), "frames": capture.n_frames, "sharing": len(windows), "own": len(plan["samples"]),
            "bytes": size}  # fmt: skip


def _capture(source, seconds, agents, cluster, on_frame, what: str, mesh=None):
    """Run `source` for `seconds`, keeping what an export needs: (crowd, driver or None, cluster
    index, agent ids, the _Capture, the roots as (translations, quaternions, scales) or None)."""
    crowd, driver, frames = _run(source, seconds, on_frame, what, initial=True)
    if crowd.pool.xp is not np:
        raise ValidationError(f"{what} reads the pose store with numpy: use a pool without xp")
    if cluster is None:
        cluster = driver.cluster if driver is not None else crowd.clusters[0]
    c = crowd.cluster_index(cluster)
    from .runtime import _agent_ids

    if mesh is not None:
        mesh.check_skeleton(crowd.skeletons[c], field=f"{what}: mesh")
    ids = np.arange(crowd.n_agents) if agents is None else _agent_ids(agents, crowd.n_agents)
    if np.any(crowd.instance_buffer()["kind"][ids, c] == 0):
        raise ValidationError(f"{what}: agent {int(ids[crowd.instance_buffer()['kind'][ids, c] == 0][0])} has "
                              f"no {cluster!r} cluster")  # fmt: skip
    capture = _Capture(crowd, c, ids)
    roots = []
    for _ in frames:
        capture.frame()
        if driver is not None:
            roots.append(_similarities(driver.roots[ids], "Driver.roots"))
    placed = tuple(np.array([r[k] for r in roots]) for k in range(3)) if roots else None
    return crowd, driver, c, ids, capture, placed


class _Capture:
    """What an export needs of a crowd run, frame by frame, without every agent's pose: every
    frame the streams of one skeleton write, run by run, and per agent part what it reads (a
    stream run and frame) or, where it reads no single stored frame, its pose."""

    def __init__(self, crowd, c: int, ids: np.ndarray):
        from .runtime import STREAMED

        self.crowd, self.c, self.ids, self.streamed = crowd, c, ids, STREAMED
        pool = crowd.pool
        skeleton = crowd.skeletons[c]
        self.members = np.array([s for s, stream in enumerate(pool.streams) if stream.skeleton.matches(skeleton)])
        n = len(pool.streams)
        self.run = np.full(n, -1)  # each stream's current run
        self.seen = np.full(n, -1)  # its clock when last looked at
        self.live = np.zeros(n, dtype=bool)
        self.runs: list = []  # per run: [stream, first frame index, last frame index kept, chunks of entries]
        self.reads, self.frames, self.own, self.poses = [], [], [], []
        self.n_own = 0

    @property
    def n_frames(self) -> int:
        return len(self.reads)

    def _keep_streams(self) -> None:
        pool = self.crowd.pool
        live = self.members[pool.running[self.members]]
        clock = pool.clock[live]
        fresh = ~self.live[live] | (clock <= self.seen[live])  # (re)started since the last look
        for s, k in zip(live[fresh].tolist(), clock[fresh].tolist()):
            first = k - int(pool.filled[s])
            self.run[s] = len(self.runs)
            self.runs.append([s, first, first - 1, []])
        wanted_streams, wanted_offsets = [], []
        for s, k in zip(live.tolist(), clock.tolist()):
            entry = self.runs[self.run[s]]
            if entry[2] + 1 < k - int(pool.filled[s]):  # a frame every update: the ring still holds the new ones
                raise ValidationError(f"export_usd: stream {s} wrote frames that were not kept")
            frames = np.arange(entry[2] + 1, k)
            wanted_streams.append(np.full(len(frames), s))
            wanted_offsets.append(k - 1 - frames)
            entry[2] = k - 1
        if wanted_streams:
            streams, offsets = np.concatenate(wanted_streams), np.concatenate(wanted_offsets)
            if len(streams):
                got = np.asarray(pool.gather(streams, offsets, self.crowd.skeletons[self.c].n_joints)).copy()
                start = 0
                for s, group in zip(live.tolist(), wanted_streams):
                    if len(group):
                        self.runs[self.run[s]][3].append(got[start : start + len(group)])
                        start += len(group)
        self.live[:] = False
        self.live[live] = True
        self.seen[live] = clock

    def frame(self) -> None:
        """Keep the crowd's current frame."""
        self._keep_streams()
        pool = self.crowd.pool
        record = self.crowd.instance_buffer()[self.ids, self.c]
        plain = (record["blend_time"] <= 0) & (record["kind"] == self.streamed)
        stream = np.where(plain, record["stream"], 0)
        offset = record["offset"].astype(np.float64)
        self.reads.append(np.where(plain, self.run[stream], -1).astype(np.int32))
        self.frames.append(np.where(plain, pool.clock[stream] - 1 - offset, np.nan))
        own = ~(plain & (offset == np.floor(offset)))
        rows = np.full(len(self.ids), -1, dtype=np.int64)
        if own.any():
            pose = self.crowd.poses(self.ids[own], self.crowd.clusters[self.c])
            self.poses.append((np.asarray(pose.rotations), np.asarray(pose.translations)))
            rows[own] = self.n_own + np.arange(int(own.sum()))
            self.n_own += int(own.sum())
        self.own.append(rows)

    def plan(self, lines: bool = True) -> dict:
        """The pose table (every run's frames, then the poses of parts that read none), the runs
        (first row, stop row, first frame index, stream name), each agent's reference (run, first
        frame index read, frames a frame) or rows, and the runs referenced. A reference is a part
        reading one run along a straight line of frames; without `lines`, at one whole offset."""
        from ..crowd.pool import entries_pose

        reads, frames, own = np.array(self.reads), np.array(self.frames), np.array(self.own)
        n_frames = len(reads)
        sizes = [sum(len(chunk) for chunk in run[3]) for run in self.runs]
        base = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        rotations, translations = [], []
        for run in self.runs:
            for chunk in run[3]:
                pose = entries_pose(chunk)
                rotations.append(np.asarray(pose.rotations))
                translations.append(np.asarray(pose.translations))
        for r, t in self.poses:
            rotations.append(r)
            translations.append(t)
        joints = self.crowd.skeletons[self.c].n_joints
        rotations = np.concatenate(rotations) if rotations else np.zeros((0, joints, 4), np.float32)
        translations = np.concatenate(translations) if translations else np.zeros((0, joints, 3), np.float32)
        first = np.array([run[1] for run in self.runs], dtype=np.int64)
        time = np.arange(n_frames)
        references, samples, used = {}, {}, {}
        for k in range(len(self.ids)):
            read, frame = reads[:, k], frames[:, k]
            if read[0] >= 0 and np.all(read == read[0]):
                slope = (frame[-1] - frame[0]) / (n_frames - 1) if n_frames > 1 else 1.0
                straight = slope > 0 and np.abs(frame[0] + slope * time - frame).max() <= LINE_TOLERANCE
                if straight and (lines or (slope == 1 and frame[0] == np.floor(frame[0]))):
                    used.setdefault(int(read[0]), len(used))
                    references[k] = (int(read[0]), float(frame[0]), float(slope))
                    continue
            whole = own[:, k] < 0
            rows = np.where(whole, 0, base[-1] + own[:, k])
            rows[whole] = base[read[whole]] + (frame[whole].astype(np.int64) - first[read[whole]])
            samples[k] = rows
        names = [self.crowd.pool.streams[run[0]].name for run in self.runs]
        return {"rotations": rotations, "translations": translations, "references": references, "samples": samples,
                "runs": [(int(base[r]), int(base[r + 1]), int(first[r]), names[r]) for r in range(len(self.runs))],
                "used": sorted(used, key=used.get)}  # fmt: skip


def _prim_name(name: str) -> str:
    """`name` as a valid USD prim name."""
    import re

    cleaned = re.sub(r"[^A-Za-z0-9_]", "_", str(name)) or "stream"
    return cleaned if not cleaned[0].isdigit() else f"s_{cleaned}"


ENGINE_FORMAT_VERSION = 2


def write_engine_buffers(source, path, seconds: float, *, on_frame=None) -> None:
    """Run `source` (a Crowd or a Driver) for `seconds` and write what a custom skinning shader
    reads to one .npz (flockkit's container: plain arrays and a JSON entry; read it with
    ``numpy.load(path)``), atomically. The layout (also in the file's metadata):

    - ``store`` (float32): the pose store before the first frame; ``lookup`` (S, M) int64: the
      float offset of (stream, ring slot), -1 past a stream's history; ``history`` (S,),
      ``bones`` (S,). Entry layout: 12 float32 per joint, rotation x, y, z, w, translation x, y,
      z, scale x, y, z, two reserved.
    - ``heads`` (F, S) int64: each stream's head slot after frame f (an agent part at offset k
      reads slot (head - k) mod history; at an offset between k and k + 1, a dilating part, it
      reads both slots and slerps rotations, lerps the rest, that far between them);
      ``written`` (F, S) int64: where in ``entries`` frame f's new head pose of stream s starts
      (-1: the stream did not run), ``entries`` float32 the new head poses, to copy into the
      store at ``lookup[s, heads[f, s]]`` before drawing frame f; ``started`` (F, S) int64: where
      in ``entries`` the first pose of a stream started during frame f before its update starts
      (-1: none), to copy into the slot before the head, ``lookup[s, (heads[f, s] - 1) mod
      history]``.
    - ``instance_<field>`` (F, N, C) for each field of ``flockkit.crowd.INSTANCE`` (stream,
      offset, target, target_offset, blend_start, blend_time, kind, target_kind, mask) and
      ``time`` (F,): α = clamp((time - blend_start) / blend_time, 0, 1) where blend_time > 0.
    - ``roots`` (F, N, 4, 4) float32 when driven: each agent's root (column vectors: a joint's
      world matrix is root @ its model-space matrix), which turns the character upright (+z) and
      scales it to metres; the metadata's ``axes`` records the character's up and forward axes
      and metres per unit it was placed with.
    """
    from .. import _npzfile
    from .runtime import INSTANCE

    heads, written, started, entries, instances, times, roots = [], [], [], [], [], [], []
    size = 0
    first: dict = {}  # stream -> its first pose, of streams that started in this frame's on_frame

    def watch(crowd, frame):
        running, clock = pool.running.copy(), pool.clock.copy()
        if on_frame is not None:
            on_frame(crowd, frame)
        first.clear()
        for s in np.flatnonzero(pool.running & (~running | (pool.clock < clock))):
            row = int(pool.lookup[s, pool.head[s]])
            first[int(s)] = pool.store[row : row + int(pool.bones[s]) * 12].copy()

    crowd, driver, frames = _run(source, seconds, watch, "write_engine_buffers")
    if crowd.pool.xp is not np:
        raise ValidationError("write_engine_buffers reads the store with numpy: use a pool without xp")
    pool = crowd.pool
    store = pool.store.copy()
    for _ in frames:
        begins = np.full(len(pool.streams), -1, dtype=np.int64)
        for s, entry in first.items():
            begins[s] = size
            entries.append(entry)
            size += len(entry)
        started.append(begins)
        starts = np.full(len(pool.streams), -1, dtype=np.int64)
        for s in np.flatnonzero(pool.running):
            row, width = int(pool.lookup[s, pool.head[s]]), int(pool.bones[s]) * 12
            starts[s] = size
            entries.append(pool.store[row : row + width].copy())
            size += width
        heads.append(pool.head.copy())
        written.append(starts)
        instances.append(crowd.instance_buffer().copy())
        times.append(crowd.time)
        if driver is not None:
            roots.append(driver.roots.astype(np.float32))
    instances = np.array(instances)
    arrays = {
        "store": store,
        "lookup": pool.lookup,
        "history": pool.history,
        "bones": pool.bones,
        "heads": np.array(heads),
        "written": np.array(written),
        "started": np.array(started),
        "entries": np.concatenate(entries) if entries else np.zeros(0, np.float32),
        "time": np.array(times),
        **{f"instance_{name}": np.ascontiguousarray(instances[name]) for name in INSTANCE.names},
    }
    if roots:
        arrays["roots"] = np.array(roots)
    layout = {
        "entry": ["rotation x", "y", "z", "w", "translation x", "y", "z", "scale x", "y", "z", "reserved", "reserved"],
        "clusters": list(crowd.clusters),
        "streams": [s.name for s in pool.streams],
        "fps": pool.fps,
        "kinds": {"none": 0, "streamed": 1, "unique": 2},
        "axes": dict(driver.axes) if driver is not None else None,
    }
    _npzfile.write(path, kind="crowd-engine-buffers", version=ENGINE_FORMAT_VERSION, arrays=arrays, metadata=layout)
