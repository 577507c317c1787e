"""A crowd run kept frame by frame, and its export for animation tools: per agent, its root
transform and its cluster's local joint poses, written to USD as one UsdSkel skeleton and
animation per agent (for small crowds: shared streams are not instanced).
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

    def export_usd(self, path, *, meters_per_unit: float = 1.0) -> None:
        """A USD stage (.usda/.usdc): /Crowd/Agent_k a UsdSkel.Root whose transform is the agent's
        root at each frame, holding a Skeleton (the joints as paths, rest and bind transforms)
        bound to a SkelAnimation with the agent's local joint rotations, translations and scales
        at each frame. Up axis z, `meters_per_unit`, frames per second the recording's; saved
        atomically. The roots place each character upright along +z at its true size (``Driver``
        turns its up axis onto +z and scales it by its metres per unit), and the stage's
        ``customLayerData["flockkit"]`` records that conversion (`axes`). usd-core (extra ``usd``)
        is needed."""
        from ..io.usd import write_skeletons

        skeleton = self.skeleton
        write_skeletons(
            path,
            joints=_joint_paths(skeleton),
            bind=skeleton.world(skeleton.rest),  # model-space rest: the bind transforms
            rest=rigid.trs(skeleton.rest.translations, skeleton.rest.rotations, skeleton.scales),
            scales=skeleton.scales,
            roots=self.roots,
            rotations=self.rotations,
            translations=self.translations,
            fps=self.fps,
            meters_per_unit=meters_per_unit,
            metadata={"character": dict(self.axes)} if self.axes else None,
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


def _run(source, seconds, on_frame, what: str):
    """(crowd, driver or None, a generator that steps `source` frame by frame for `seconds`,
    calling ``on_frame(crowd, frame)`` before each update)."""
    from .drive import Driver
    from .runtime import Crowd

    driver = source if isinstance(source, Driver) else None
    crowd = driver.crowd if driver is not None else source
    if not isinstance(crowd, Crowd):
        raise ValidationError(f"{what} needs a flockkit.Crowd or a crowd Driver; got {type(source).__name__}")
    seconds = validate.number(seconds, f"{what}: seconds", minimum=0, strict=True)

    def frames():
        for frame in range(int(round(seconds * crowd.pool.fps))):
            if on_frame is not None:
                on_frame(crowd, frame)
            if driver is not None:
                driver.step()
            else:
                crowd.update()
            yield frame

    return crowd, driver, frames()


def record(source, seconds: float, *, agents=None, cluster=None, on_frame=None) -> CrowdRecording:
    """Run `source` (a ``flockkit.Crowd``, or a ``flockkit.crowd.Driver`` that moves one) for
    `seconds` and keep, each frame after its update, the roots, local poses and streams of
    `agents` (default all) in `cluster` (default the driver's, or the crowd's first).
    ``on_frame(crowd, frame)`` is called before each update (to start transitions)."""
    crowd, driver, frames = _run(source, seconds, on_frame, "record")
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
