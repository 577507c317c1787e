"""The crowd runtime (paper 003, sections 4.2-4.4): agents split into part clusters, each reading
a shared stream at its own offset (or a unique slot), transitions with blends, time dilation.

Agents may take their motion from their clips (``root_motion``): each frame an agent's root
advances by what its part in that cluster read since the frame before (the stream's root motion
between the two frames it read, so offsets, dilation and blends count). Part clusters may hang on
a joint of another (``Hook``: a flag in a hand, a head on a neck), and procedural overrides
(``LookAt``) change declared joints of the blended local pose, per agent, after blending (section
4.6), before anything reads it.

The state of every agent part is its instance-buffer record (what a skinning shader reads,
Listing 3): the stream it reads and its offset, the stream it blends to and that offset, when the
blend started and how long it lasts, and the agent's visibility mask. Each ``update`` advances
one frame; work per frame grows with the parts that change (dilating, blending), not the crowd.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from .. import rigid, validate
from ..errors import ValidationError
from ..skeleton import Event, Pose, compose_ground, ground_matrices, relative_ground
from . import _kernels
from .pool import ENTRY_FLOATS, StreamPool, UniquePool, blend_entries, entries_pose, namespace

__all__ = ["Crowd", "CrowdEvent", "Hook", "LookAt", "INSTANCE", "NONE", "STREAMED", "UNIQUE", "DILATION_RATE",
           "MAX_DILATION_RATE", "MAX_LOD"]  # fmt: skip

NONE, STREAMED, UNIQUE = 0, 1, 2  # what an agent part reads (kind, target_kind)
INSTANCE = np.dtype(
    [
        ("stream", "<i4"),  # stream (or unique slot) read; -1: none
        ("offset", "<f4"),  # frames behind its head
        ("target", "<i4"),  # stream (or slot) blended to; -1: not blending
        ("target_offset", "<f4"),
        ("blend_start", "<f4"),  # crowd time (s) the blend started
        ("blend_time", "<f4"),  # seconds; 0: not blending
        ("kind", "u1"),  # NONE, STREAMED or UNIQUE
        ("target_kind", "u1"),
        ("mask", "<u2"),  # the agent's visible clusters, bit c for cluster c
    ]
)
# The default time dilation's changeRate when no time_to_dilate is given: the farthest part moves
# a quarter frame per frame, playing at three quarters speed while the crowd spreads out.
DILATION_RATE = 0.25
# A part that dilates plays at (1 - its rate) speed, and a Stopped stream holds only the frames it
# has written since it started: at most this changeRate, no part falls below half speed (a rate
# of 1 would freeze it at the stream's first frame, above 1 play it backwards).
MAX_DILATION_RATE = 0.5
# Levels of detail: an agent at level k is refreshed every 2^k frames (1, 2, 4, 8); past 8 frames
# (a quarter second at 30 fps) a held part's dilation and blend landing lag visibly.
MAX_LOD = 3


@attrs.frozen
class CrowdEvent:
    """An event a stream (or a unique slot, `unique`) reached at its head this frame; an agent
    part reading that stream at offset k reaches it k frames later."""

    stream: int
    event: Event
    unique: bool = False


def _merge(xp, first, first_rows: np.ndarray, second, second_rows: np.ndarray):
    """Rows of `first` and `second` put back in the order their row numbers give (concatenation
    and one take: no integer-array assignment, which the array API standard lacks)."""
    order = np.argsort(np.concatenate([first_rows, second_rows]), kind="stable")
    return xp.take(xp.concat([first, second], axis=0), xp.asarray(order), axis=0)


def interpolate_entries(a, b, weight):
    """Store entries `a` (n, J, 12) moved `weight` (n,) of the way to `b`, as a clip moves between
    two keys (``Pose.interpolate``): rotations slerped (the shorter way round, at a steady angular
    speed), translations and scales linearly; weight 0 gives `a`. Array API calls only, so a
    store on a GPU reads between frames through the same code."""
    xp = namespace(a)
    w = xp.reshape(xp.astype(weight, a.dtype), (-1, 1, 1))
    out = b - a  # every field lerped, then the rotations replaced by the slerp
    out *= w
    out += a
    qa, qb = a[..., 0:4], b[..., 0:4]
    dot = xp.vecdot(qa, qb)[..., None]
    sign = xp.where(dot < 0, -xp.ones_like(dot), xp.ones_like(dot))  # -b is b's rotation, nearer
    # float32 leaves the angle of nearly equal keys uncertain by ~3e-4 rad, but the weights below
    # depend on it only at second order, and they are scaled to give a unit result
    angle = xp.acos(xp.minimum(dot * sign, xp.ones_like(dot)))
    sine = xp.sin(angle)
    tiny = sine < 1e-4  # (nearly) one rotation: the linear weights, the slerp's limit
    safe = xp.where(tiny, xp.ones_like(sine), sine)
    wa = xp.where(tiny, 1 - w, xp.sin((1 - w) * angle) / safe)
    wb = xp.where(tiny, w, xp.sin(w * angle) / safe) * sign
    length = xp.sqrt(wa * wa + wb * wb + 2 * wa * wb * dot)  # of wa qa + wb qb, from the weights alone
    out[..., 0:4] = (wa / length) * qa + (wb / length) * qb
    return out


def _agent_ids(agents, n_agents: int) -> np.ndarray:
    ids = np.atleast_1d(np.asarray(agents))
    if ids.ndim != 1 or (ids.size and ids.dtype.kind not in "iu"):
        raise ValidationError(f"agents must be agent ids (integers); got {agents!r}")
    ids = ids.astype(np.int64)
    if ids.size and (ids.min() < 0 or ids.max() >= n_agents):
        bad = int(ids[(ids < 0) | (ids >= n_agents)][0])
        raise ValidationError(f"unknown agent id {bad}; the crowd has agents 0..{n_agents - 1}")
    counts = np.bincount(ids) if ids.size > 1 else np.zeros(1, dtype=np.int64)  # cheaper than sorting them
    if counts.max() > 1:
        raise ValidationError(f"agents must not repeat an id; {int(np.argmax(counts))} is given twice")
    return ids


def _offset(value) -> np.ndarray:
    m = np.eye(4) if value is None else np.array(value, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)) or not np.allclose(m[3], [0, 0, 0, 1]):
        raise ValidationError(f"Hook.offset must be a finite 4 x 4 affine matrix (last row 0 0 0 1); got {value!r}")
    m.setflags(write=False)
    return m


@attrs.frozen(kw_only=True)
class Hook:
    """Part cluster `part` hangs on joint `joint` of cluster `parent` (section 4.2: each part's
    static hook on its parent): the part's model space is placed at that joint's world transform
    times `offset` (4 x 4, default the identity), whatever either part plays, so that a flag stays
    in the hand that waves it."""

    part: str = attrs.field()
    parent: str = attrs.field()
    joint: str = attrs.field()
    offset: np.ndarray = attrs.field(default=None, converter=_offset, eq=False)


class PoseOverride:
    """What a procedural per-bone override offers (paper 003, section 4.6), declared rather than
    found out: ``joints``, the names of the joints it changes (the crowd takes only those from
    it), and ``apply(pose, *, skeleton, agents, origins, time)``, which returns the local Pose
    (n, J) of `agents` (ids) given their blended local `pose` (n, J, float32), `origins` (n, 4,
    4) the world transforms of their part's model space (``Crowd.placement`` times the part's
    hook) and the crowd's `time`. It must be a function of those: poses are read any number of
    times a frame. ``LookAt`` is one."""

    joints: tuple = ()

    def apply(self, pose, *, skeleton, agents, origins, time):  # pragma: no cover - the protocol
        raise NotImplementedError


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3 - 2 * u)


class LookAt(PoseOverride):
    """Turn joint `joint` (a head) so that its `forward` axis (in the joint's own frame) points at
    each agent's target, by the smallest rotation, at most `max_angle` radians from where the
    blended pose points it (a cone: beyond it the joint turns `max_angle` towards the target),
    times each agent's weight, which eases (smoothstep) to its new value over `blend_time`
    seconds of crowd time. Targets are world points; ``origins`` bring them into the agent's
    model space. Every agent starts with weight 0 (not looking).

    Parameters
    ----------
    joint : str
    n_agents : int
    forward : (3,)
        The joint's axis that should point at the target, in the joint's local frame.
    max_angle : float
        Radians, in (0, pi].
    blend_time : float
        Seconds (>= 0) over which a weight eases to its new value.
    """

    def __init__(self, joint: str, *, n_agents: int, forward=(0.0, 0.0, 1.0), max_angle: float = math.radians(60),
                 blend_time: float = 0.3):  # fmt: skip
        if not isinstance(joint, str) or not joint:
            raise ValidationError(f"LookAt.joint must be a joint name; got {joint!r}")
        self.joint = joint
        self.joints = (joint,)
        self.n_agents = validate.integer(n_agents, "LookAt.n_agents", minimum=1)
        axis = np.asarray(forward, dtype=np.float64)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-9:
            raise ValidationError(f"LookAt.forward must be a non-zero 3-vector; got {forward!r}")
        self.forward = axis / np.linalg.norm(axis)
        self.max_angle = validate.number(max_angle, "LookAt.max_angle", minimum=0, maximum=math.pi, strict=True)
        self.blend_time = validate.number(blend_time, "LookAt.blend_time", minimum=0)
        self.targets = np.zeros((self.n_agents, 3))
        self._from = np.zeros(self.n_agents)
        self._to = np.zeros(self.n_agents)
        self._since = np.zeros(self.n_agents)

    def weights(self, time: float) -> np.ndarray:
        """Each agent's weight (N,) at crowd `time`."""
        if self.blend_time == 0:
            return self._to.copy()
        return self._from + (self._to - self._from) * _smoothstep((time - self._since) / self.blend_time)

    def look(self, agents, targets, *, time: float, weight: float = 1.0) -> None:
        """From crowd `time` on, `agents` look at world `targets` ((3,) or (n, 3)), their weights
        easing from where they are to `weight`."""
        ids = _agent_ids(agents, self.n_agents)
        points = np.broadcast_to(np.asarray(targets, dtype=np.float64), (len(ids), 3))
        if not np.all(np.isfinite(points)):
            raise ValidationError("LookAt.look: targets must be finite world points")
        weight = validate.number(weight, "LookAt.look: weight", minimum=0, maximum=1)
        self._ease(ids, weight, time)
        self.targets[ids] = points

    def release(self, agents, *, time: float) -> None:
        """From crowd `time` on, `agents`' weights ease to 0 (their joint back to its animation)."""
        self._ease(_agent_ids(agents, self.n_agents), 0.0, time)

    def _ease(self, ids, weight, time) -> None:
        time = validate.number(time, "LookAt: time")
        self._from[ids] = self.weights(time)[ids]
        self._to[ids], self._since[ids] = weight, time

    def apply(self, pose, *, skeleton, agents, origins, time):
        j = skeleton.index(self.joint)
        chain = []  # the joint's ancestors, root first
        k = skeleton.parents[j]
        while k >= 0:
            chain.insert(0, k)
            k = skeleton.parents[k]
        n = len(agents)
        above = np.broadcast_to(np.eye(4), (n, 4, 4))
        for k in chain:  # the parent's model-space transform, down the chain only
            local = rigid.trs(pose.translations[:, k], pose.rotations[:, k], skeleton.scales[k])
            above = above @ local
        turn = above[:, :3, :3] / np.linalg.norm(above[:, :3, :3], axis=1, keepdims=True)  # the parent's rotation
        head = above @ np.append(pose.translations[:, j].astype(np.float64), np.ones((n, 1)), axis=1)[..., None]
        rotation = rigid.quaternion_matrix(pose.rotations[:, j].astype(np.float64))
        facing = turn @ rotation @ self.forward  # (n, 3) in model space
        target = np.linalg.solve(origins, np.append(self.targets[agents], np.ones((n, 1)), axis=1)[..., None])
        wanted = (target - head)[:, :3, 0]
        wanted /= np.maximum(np.linalg.norm(wanted, axis=1, keepdims=True), 1e-12)
        axis = np.cross(facing, wanted)
        sine, cosine = np.linalg.norm(axis, axis=1), np.sum(facing * wanted, axis=1)
        angle = np.arctan2(sine, cosine)
        # opposite directions: any axis across the facing; none: no turn
        across = np.cross(facing, np.eye(3)[np.argmin(np.abs(facing), axis=1)])
        axis = np.where((sine < 1e-12)[:, None], across, axis)
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        angle = np.minimum(angle, self.max_angle) * self.weights(time)[agents]
        local_axis = np.einsum("nji,nj->ni", turn, axis)  # into the parent's frame
        half = angle[:, None] / 2
        change = np.concatenate([np.sin(half) * local_axis, np.cos(half)], axis=1)
        rotations = np.array(pose.rotations, dtype=np.float32)
        rotations[:, j] = rigid.quaternion_product(change, pose.rotations[:, j].astype(np.float64))
        return Pose._adopt(rotations, pose.translations)


class Crowd:
    """Agents whose part clusters read shared streams (sections 4.2-4.4).

    Parameters
    ----------
    pool : StreamPool
    n_agents : int
    clusters : mapping of str to int or (n_agents,) ints
        Per cluster (body, scarf, flag, ...), the stream each agent's part reads at the start; -1
        where an agent does not have the cluster. All streams of a cluster share one skeleton.
    unique : UniquePool, optional
        Slots for per-agent animations (``transition_to_unique``).
    seed : int, optional
        For the agents' starting offsets and the targets of time dilation.
    root_motion : str, optional
        The cluster whose streams move the agents (``roots``): each frame an agent's root
        advances by the root motion (``Capabilities.root_motion``) of what its part in that
        cluster read since the frame before, between the two frames read in the stream (so a
        part's offset, time dilation and playback rate count, and loops accumulate), and while
        blending by both streams' motion mixed by α. Parts reading a unique slot, or streams whose
        controller offers none, do not move. None (the default): agents do not move (a ``Driver``
        places them on trajectories).
    hooks : sequence of Hook
        Clusters hung on a joint of another (``poses(space="world")`` places them there). A
        cluster hangs on one parent at most, hooks form no cycle, and every agent with a hooked
        part has its parent part.
    overrides : mapping of str to sequence of PoseOverride
        Per cluster, procedural overrides (``LookAt``) applied in order to the blended local pose
        of every agent whenever it is read (``entries``, ``poses``), changing only the joints each
        declares (section 4.6; the GPU path of ``flockkit.crowd.textures`` does not run them).

    The pool is run until every Running stream has its whole history, then each part gets a
    random offset in it, so that agents sharing a stream differ from the first frame.

    Attributes
    ----------
    placement : (N, 4, 4) float64
        Each agent's model space in the world (identity until set; a ``Driver`` sets its roots
        there every frame): what ``LookAt`` turns world targets into model space with.
    """

    def __init__(self, pool: StreamPool, *, n_agents: int, clusters, unique: UniquePool | None = None, seed=None,
                 root_motion=None, hooks=(), overrides=None):  # fmt: skip
        if not isinstance(pool, StreamPool):
            raise ValidationError(f"Crowd needs a flockkit.crowd.StreamPool; got {type(pool).__name__}")
        if unique is not None and not isinstance(unique, UniquePool):
            raise ValidationError(f"Crowd unique must be a flockkit.crowd.UniquePool; got {type(unique).__name__}")
        self.pool, self.unique = pool, unique
        self.n_agents = validate.integer(n_agents, "n_agents", minimum=1)
        if not isinstance(clusters, dict) or not clusters or len(clusters) > 16:
            raise ValidationError("Crowd clusters must be a mapping of 1 to 16 cluster names to streams")
        self.clusters = tuple(clusters)
        self.rng = np.random.default_rng(seed)
        self.time = 0.0
        self.frame = 0
        n, c = self.n_agents, len(self.clusters)
        # the instance buffer, the dilation state and the temporaries of an update, per agent part
        validate.allocation(float(n) * c * (INSTANCE.itemsize + 8) * 4, f"Crowd: {n} agents x {c} clusters",
                            itemsize=1)  # fmt: skip
        buffer = np.zeros((n, c), dtype=INSTANCE)
        buffer["stream"] = buffer["target"] = -1
        self.skeletons = []
        for k, name in enumerate(self.clusters):
            streams = np.broadcast_to(np.asarray(clusters[name]), (n,))
            if streams.dtype.kind not in "iu":
                raise ValidationError(f"Crowd clusters[{name!r}] must be stream ids (-1: the agent lacks it)")
            has = streams >= 0
            if not has.any():
                raise ValidationError(f"Crowd clusters[{name!r}]: no agent has this cluster")
            used = pool.check_streams(np.unique(streams[has]), field=f"Crowd clusters[{name!r}]")
            skeleton = pool.streams[used[0]].skeleton
            for s in used:
                if not skeleton.matches(pool.streams[s].skeleton):
                    raise ValidationError(
                        f"Crowd clusters[{name!r}]: stream {s}'s skeleton does not match stream {used[0]}'s; "
                        "a cluster's streams share one skeleton"
                    )
            self.skeletons.append(skeleton)
            buffer["stream"][:, k] = np.where(has, streams, -1)
            buffer["kind"][:, k] = np.where(has, STREAMED, NONE)
        buffer["mask"] = np.sum((buffer["kind"] != NONE) * (1 << np.arange(c)), axis=1, keepdims=True).astype(np.uint16)
        self._buffer = buffer
        self._dilate_to = np.full((n, c), np.nan, dtype=np.float32)  # NaN: not dilating
        self._rate = np.zeros((n, c), dtype=np.float32)
        self._changing = np.zeros(0, dtype=np.int64)  # flat indices (agent * C + cluster) dilating or blending
        self._since = np.zeros((n, c), dtype=np.int64)  # the frame each part's dilation last moved
        self._lod = np.zeros(n, dtype=np.uint8)  # each agent's level of detail (set_lod)
        reading = buffer["kind"] == STREAMED
        pool.acquire(buffer["stream"][reading])
        for _ in range(int(pool.history.max()) - 1):  # fill every running stream's history
            pool.advance()
        streams = buffer["stream"][reading]
        available = np.minimum(pool.filled[streams], pool.history[streams])
        buffer["offset"][reading] = self.rng.integers(0, available)
        self.placement = np.tile(np.eye(4), (n, 1, 1))
        self._set_hooks(tuple(hooks))
        self._set_overrides({} if overrides is None else overrides)
        # root motion: the cluster (index) that moves agents, each agent's root (a ground
        # transform) and what its part read last frame in its source and target streams
        self.root_motion = None if root_motion is None else self.clusters[self.cluster_index(root_motion)]
        self._ground = np.zeros((n, 4))
        self._read_source = np.zeros((n, 4))
        self._read_target = np.zeros((n, 4))
        if self.root_motion is not None:
            r = self.cluster_index(self.root_motion)
            self._read_source = self._root_reads(buffer["kind"][:, r], buffer["stream"][:, r], buffer["offset"][:, r])

    def _set_hooks(self, hooks) -> None:
        self.hooks = {}
        for hook in hooks:
            if not isinstance(hook, Hook):
                raise ValidationError(f"Crowd hooks must be flockkit.crowd.Hook; got {type(hook).__name__}")
            c, p = self.cluster_index(hook.part), self.cluster_index(hook.parent)
            if c == p or hook.part in self.hooks:
                raise ValidationError(f"Crowd hooks: cluster {hook.part!r} hangs on itself or on two parents")
            self.skeletons[p].index(hook.joint)
            lacking = np.flatnonzero((self._buffer["kind"][:, c] != NONE) & (self._buffer["kind"][:, p] == NONE))
            if len(lacking):
                raise ValidationError(f"Crowd hooks: agent {int(lacking[0])} has a {hook.part!r} part hung on "
                                      f"{hook.parent!r} but no {hook.parent!r} part")  # fmt: skip
            self.hooks[hook.part] = hook
        for start in self.hooks:
            seen, part = {start}, start
            while part in self.hooks:
                part = self.hooks[part].parent
                if part in seen:
                    raise ValidationError(f"Crowd hooks form a cycle through cluster {part!r}")
                seen.add(part)

    def _set_overrides(self, overrides) -> None:
        if not isinstance(overrides, dict):
            raise ValidationError("Crowd overrides must be a mapping of cluster names to sequences of overrides")
        self.overrides = {}
        for name, found in overrides.items():
            c = self.cluster_index(name)
            found = tuple(found) if isinstance(found, (list, tuple)) else (found,)
            for override in found:
                joints = getattr(override, "joints", None)
                if not callable(getattr(override, "apply", None)) or not isinstance(joints, tuple) or not joints:
                    raise ValidationError(
                        f"Crowd overrides[{name!r}]: {type(override).__name__} is not a pose override (a non-empty "
                        "tuple `joints` of the joints it changes and `apply`)"
                    )
                for joint in joints:
                    self.skeletons[c].index(joint)
                n = getattr(override, "n_agents", self.n_agents)
                if n != self.n_agents:
                    raise ValidationError(f"Crowd overrides[{name!r}]: made for {n} agents; the crowd has "
                                          f"{self.n_agents}")  # fmt: skip
            self.overrides[name] = found

    # -- root motion ----------------------------------------------------------------------------

    def _root_reads(self, kind, stream, offset) -> np.ndarray:
        """Where the stream each part reads had taken its root by the frame it reads (n, 4); zero
        for parts that read no stream."""
        out = np.zeros((len(kind), 4))
        streamed = np.flatnonzero(kind == STREAMED)
        out[streamed] = self.pool.root_at(stream[streamed], offset[streamed])
        return out

    def _advance_roots(self, ids=None) -> None:
        """Each agent of `ids` (default all) moves by what its root-motion part read since it last
        moved (the last frame, or its last refresh at a level of detail above 0; a blend mixes the
        two streams' steps by α now)."""
        ids = np.arange(self.n_agents) if ids is None else ids
        r = self.cluster_index(self.root_motion)
        record = self._buffer[ids, r]
        up = self.skeletons[r].up_axis
        now = self._root_reads(record["kind"], record["stream"], record["offset"])
        step = relative_ground(self._read_source[ids], now, up)
        self._read_source[ids] = now
        blending = np.flatnonzero(record["blend_time"] > 0)
        if len(blending):
            b, moving = record[blending], ids[blending]
            target = self._root_reads(b["target_kind"], b["target"], b["target_offset"])
            into = relative_ground(self._read_target[moving], target, up)
            self._read_target[moving] = target
            alpha = np.clip((self.time - b["blend_start"]) / b["blend_time"], 0, 1)[:, None]
            step[blending] = (1 - alpha) * step[blending] + alpha * into
        step[record["kind"] == NONE] = 0
        self._ground[ids] = compose_ground(self._ground[ids], step, up)

    def roots(self) -> np.ndarray:
        """Each agent's root (N, 4, 4) float64 in its character's model space and units: where the
        root motion of its ``root_motion`` cluster has taken it since the start (the identity
        there, and for a crowd without root motion)."""
        if self.root_motion is None:
            return np.tile(np.eye(4), (self.n_agents, 1, 1))
        return ground_matrices(self._ground, self.skeletons[self.cluster_index(self.root_motion)].up_axis)

    # -- checks ---------------------------------------------------------------------------------

    def cluster_index(self, cluster) -> int:
        """The index of `cluster` (its bit in the visibility mask, its column of the instance
        buffer); a ValidationError naming the clusters if there is none."""
        if cluster not in self.clusters:
            raise ValidationError(
                f"unknown cluster {cluster!r}; the crowd's clusters are {', '.join(map(repr, self.clusters))}"
            )
        return self.clusters.index(cluster)

    def _parts(self, agents, cluster) -> tuple[np.ndarray, int]:
        ids, c = _agent_ids(agents, self.n_agents), self.cluster_index(cluster)
        lacking = ids[self._buffer["kind"][ids, c] == NONE]
        if len(lacking):
            raise ValidationError(f"agent {int(lacking[0])} has no {cluster!r} cluster to transition")
        return ids, c

    @staticmethod
    def _seconds(value, field: str, *, optional: bool = False):
        if optional and value is None:
            return None
        return validate.number(value, field, minimum=0, strict=True)

    # -- transitions ----------------------------------------------------------------------------

    def transition_to_streamed(self, agents, cluster, stream, blend_time, *, time_to_dilate=None, offsets=None) -> None:
        """Blend `agents`' part `cluster` over `blend_time` seconds to shared `stream` (section 4.3).

        Into a Running stream, each part blends to a random offset within the history written.
        Into a Stopped stream (which starts now), every part starts at offset 0, the head, and
        time dilation (Listing 2) moves each offset to a random whole-frame target in [0, M_new],
        M_new = history - 1 (the whole ring buffer), at changeRate = (M_new - M) /
        (time_to_dilate * fps) frames per frame, M = 0. Offsets move by fractions of a frame and
        parts read between the two frames either side (``poses``), so a dilating part shows a
        new pose every frame, at (1 - its rate) speed. Two departures from the listing, both so
        that parts keep moving and spread at once: changeRate is at most MAX_DILATION_RATE (a
        Stopped stream holds only the frames written since it started, and a part must not drop
        below half speed), so a spread that would need more takes M_new / (MAX_DILATION_RATE *
        fps) seconds instead of `time_to_dilate`; and each part moves at changeRate * target /
        M_new, so every part arrives together at the end instead of the parts with far targets
        moving in step at changeRate until they arrive. Without `time_to_dilate`, changeRate is
        DILATION_RATE. `time_to_dilate` given for a Running stream applies the same from offset
        0. `offsets` (one per agent, or one for all) chooses the target offsets in a Running
        stream instead. A part already blending first lands on its blend's target. Refused calls
        change nothing.
        """
        ids, c = self._parts(agents, cluster)
        (k,) = self.pool.check_streams(stream)
        if not self.skeletons[c].matches(self.pool.streams[k].skeleton):
            raise ValidationError(
                f"stream {k}'s skeleton ({self.pool.bones[k]} joints) does not match cluster {cluster!r}'s "
                f"({self.skeletons[c].n_joints} joints)"
            )
        blend_time = self._seconds(blend_time, "blend_time")
        time_to_dilate = self._seconds(time_to_dilate, "time_to_dilate", optional=True)
        was_running = bool(self.pool.running[k])
        if offsets is not None:
            chosen = np.broadcast_to(np.asarray(offsets), (len(ids),))
            if not was_running or time_to_dilate is not None:
                raise ValidationError(
                    "offsets are for a Running stream without time dilation (a Stopped one starts at 0)"
                )
            if chosen.dtype.kind not in "iu" or chosen.min() < 0 or chosen.max() >= self.pool.filled[k]:
                raise ValidationError(
                    f"offsets must be integers in 0..{self.pool.filled[k] - 1} (the frames stream {k} holds); "
                    f"got {offsets!r}"
                )
        self._land(ids, c)
        self.pool.acquire(np.full(len(ids), k))
        history = int(self.pool.history[k])
        if was_running and time_to_dilate is None:
            if offsets is None:
                chosen = self.rng.integers(0, self.pool.filled[k], size=len(ids))
            offsets = chosen.astype(np.float32)
            self._dilate_to[ids, c] = np.nan
        else:
            offsets = np.zeros(len(ids), dtype=np.float32)
            spread = history - 1  # M_new
            if time_to_dilate is None:
                rate = DILATION_RATE
            else:
                rate = min(spread / (time_to_dilate * self.pool.fps), MAX_DILATION_RATE)
            targets = self.rng.integers(0, spread + 1, size=len(ids))
            self._dilate_to[ids, c] = targets
            self._rate[ids, c] = rate * targets / max(spread, 1)
        self._start_blend(ids, c, STREAMED, k, offsets, blend_time)

    def matching_offsets(self, agents, cluster, stream) -> np.ndarray:
        """For each of `agents`' part `cluster`, the offset into Running `stream` whose stored
        motion is nearest the part's: its pose now and a frame ago against the stream's at the
        offset and a frame older (local rotations, the sum over joints of 1 - cos² of the angles
        between them; two frames tell a leg swinging forward from one swinging back through the
        same pose). Where a part switching to another rate of one motion enters, so that it keeps
        its step and its own phase (and the crowd its desynchronisation)."""
        ids, c = self._parts(agents, cluster)
        (k,) = self.pool.check_streams(stream)
        if not self.pool.running[k]:
            raise ValidationError(f"stream {k} is Stopped: a part entering it starts at offset 0")
        xp, bones = self.pool.xp, self.skeletons[c].n_joints
        held = np.arange(self.pool.filled[k])
        frames = self.pool.gather(np.full(len(held), k), held, bones)[..., :4]  # (H, J, 4), newest first
        older = xp.concat([frames[1:], frames[-1:]])
        score = 0
        for stored, lag in ((frames, 0), (older, 1)):
            mine = self._entries(ids, c, lag)[..., :4]  # (n, J, 4)
            cosines = xp.sum(xp.astype(mine, xp.float64)[:, None] * xp.astype(stored, xp.float64)[None], axis=-1)
            score = score + xp.sum(cosines * cosines, axis=-1)  # (n, H)
        return np.asarray(xp.argmax(score, axis=1)).astype(np.int64)

    def assign(self, agents, cluster, stream) -> None:
        """Put `agents`' part `cluster` on `stream` at once, without a blend (setting a crowd up,
        not animating it): at random offsets within what a Running stream holds, or at 0 with
        the default time dilation on a Stopped one."""
        ids, c = self._parts(agents, cluster)
        self.transition_to_streamed(ids, cluster, stream, blend_time=1.0)
        self._land(ids, c)

    def transition_to_unique(self, agents, cluster, slot, blend_time) -> None:
        """Blend `agents`' part `cluster` over `blend_time` seconds to unique slot `slot`, which
        they read at its current pose."""
        ids, c = self._parts(agents, cluster)
        if self.unique is None:
            raise ValidationError("this crowd has no UniquePool: pass unique= to Crowd")
        (k,) = self.unique.check_slots(slot)
        if not self.skeletons[c].matches(self.unique.controllers[k].skeleton):
            raise ValidationError(f"unique slot {k}'s skeleton does not match cluster {cluster!r}'s")
        blend_time = self._seconds(blend_time, "blend_time")
        self._land(ids, c)
        self._dilate_to[ids, c] = np.nan
        self._start_blend(ids, c, UNIQUE, k, np.zeros(len(ids), dtype=np.float32), blend_time)

    def _start_blend(self, ids, c, kind, target, offsets, blend_time) -> None:
        if self.root_motion is not None and self.clusters[c] == self.root_motion:
            self._read_target[ids] = self._root_reads(np.full(len(ids), kind), np.full(len(ids), target), offsets)
        self._changing = np.union1d(self._changing, ids * len(self.clusters) + c)
        self._since[ids, c] = self.frame
        record = self._buffer[ids, c]
        record["target_kind"], record["target"], record["target_offset"] = kind, target, offsets
        record["blend_start"], record["blend_time"] = self.time, blend_time
        self._buffer[ids, c] = record

    def _land(self, ids, c) -> None:
        """Parts of `ids` in cluster `c` that are blending take their blend's target now."""
        blending = ids[self._buffer["blend_time"][ids, c] > 0]
        if len(blending):
            self._collapse(blending, np.full(len(blending), c))

    def _collapse(self, agents: np.ndarray, clusters: np.ndarray) -> None:
        """Finished (or interrupted) blends: the target becomes the source; the source stream
        loses a user."""
        record = self._buffer[agents, clusters]
        leaving = record["stream"][record["kind"] == STREAMED]
        record["kind"], record["stream"], record["offset"] = (
            record["target_kind"],
            record["target"],
            record["target_offset"],
        )
        record["target_kind"], record["target"], record["target_offset"] = NONE, -1, 0
        record["blend_start"], record["blend_time"] = 0, 0
        self._buffer[agents, clusters] = record
        self.pool.release(leaving)
        if self.root_motion is not None:
            rooted = agents[clusters == self.cluster_index(self.root_motion)]
            self._read_source[rooted] = self._read_target[rooted]

    # -- frames ---------------------------------------------------------------------------------

    def update(self, dt=None) -> list[CrowdEvent]:
        """Advance one frame: Running streams write their heads, unique slots evaluate, offsets
        dilate, blends advance and finished ones land on their targets (streams left without
        users stop if Stopped by default). Streams always move one frame (their history is in
        frames, section 4.3's fixed-step simulation); blends run on the crowd's clock, which
        advances `dt` seconds (default 1 / pool.fps), as a shader's global timer does. Returns
        the events the streams' heads reached.

        Agents at a level of detail above 0 (``set_lod``) are refreshed only on their frames
        (``due``): their parts' offsets dilate by the frames since they last moved, their
        finished blends land and their roots move then, and their instance-buffer records are
        held in between, so the work of a frame falls with the share of agents due."""
        dt = 1.0 / self.pool.fps if dt is None else validate.number(dt, "update: dt", minimum=0, strict=True)
        events = [CrowdEvent(stream=s, event=e) for s, e in self.pool.advance()]
        if self.unique is not None:
            events += [CrowdEvent(stream=s, event=e, unique=True) for s, e in self.unique.advance()]
        self.frame += 1
        self.time += dt
        flat, held = self._changing, self._changing[:0]
        lod = bool(self._lod.any())
        if lod:
            due = self._due(flat // len(self.clusters))
            flat, held = flat[due], flat[~due]
        if not len(flat):
            if self.root_motion is not None:
                self._advance_roots(np.flatnonzero(self.due()) if lod else None)
            self._changing = held
            return events
        agents, clusters = np.divmod(flat, len(self.clusters))
        buffer = self._buffer  # field by field: gathering whole records is slower
        blending = buffer["blend_time"][agents, clusters] > 0
        goal = self._dilate_to[agents, clusters]
        dilating = ~np.isnan(goal)
        for field, stream, which in (
            ("target_offset", "target", dilating & blending),
            ("offset", "stream", dilating & ~blending),
        ):
            a, c = agents[which], clusters[which]
            if not len(a):
                continue
            rate = self._rate[a, c]
            if lod:  # the frames since the part last moved (1 at level 0)
                rate = rate * (self.frame - self._since[a, c]).astype(np.float32)
            step, target = buffer[field][a, c] + rate, goal[which]
            # float32 steps that sum to the target can fall short of it by rounding: within a
            # thousandth of a frame is there
            step = np.where(step >= target - 1e-3, target, step)
            moved = np.minimum(step, self.pool.filled[buffer[stream][a, c]] - 1)
            buffer[field][a, c] = moved
            arrived = moved >= target
            self._dilate_to[a[arrived], c[arrived]] = np.nan
            goal[np.flatnonzero(which)[arrived]] = np.nan
        self._since[agents, clusters] = self.frame
        if self.root_motion is not None:
            self._advance_roots(np.flatnonzero(self.due()) if lod else None)
        finished = blending & (
            self.time - buffer["blend_start"][agents, clusters] >= buffer["blend_time"][agents, clusters] - 1e-6
        )
        if finished.any():
            self._collapse(agents[finished], clusters[finished])
        kept = flat[~np.isnan(goal) | (blending & ~finished)]
        self._changing = np.concatenate([held, kept]) if len(held) else kept  # any order (union1d sorts)
        return events

    # -- levels of detail -----------------------------------------------------------------------

    def _due(self, agents) -> np.ndarray:
        """Whether each of `agents` is refreshed this frame: level k every 2^k frames, agent a on
        the frames f with (f + a) mod 2^k = 0 (staggered, so a level's work spreads evenly)."""
        period = np.left_shift(1, self._lod[agents].astype(np.int64))
        return ((self.frame + agents) & (period - 1)) == 0

    def due(self) -> np.ndarray:
        """Each agent's refresh (N,) bool: True where the last ``update`` refreshed it (every agent
        at level 0)."""
        return self._due(np.arange(self.n_agents))

    @property
    def lod(self) -> np.ndarray:
        """Each agent's level of detail (N,) uint8, read-only: 0 to MAX_LOD, refreshed every 2^level
        frames."""
        view = self._lod.view()
        view.setflags(write=False)
        return view

    def set_lod(self, agents, level) -> None:
        """Set `agents`' level of detail (one level for all, or one each): integers 0 to MAX_LOD.
        At level k an agent is refreshed every 2^k frames, staggered by its id (``due``): its
        instance-buffer records, dilation, blend landing and root motion move then and are held
        in between, and ``refresh`` rewrites its pose then. A skinning shader goes on playing
        a held part from its stream (the stream's head moves every frame); what is held is the
        part's offset and blend state. A new level takes effect at the next update."""
        ids = _agent_ids(agents, self.n_agents)
        levels = np.asarray(level)
        if levels.dtype.kind not in "iu" or levels.ndim > 1 or (levels.ndim == 1 and len(levels) != len(ids)):
            raise ValidationError(f"lod: levels must be integers 0..{MAX_LOD}, one for all agents or one each; "
                                  f"got {level!r}")  # fmt: skip
        if levels.size and (levels.min() < 0 or levels.max() > MAX_LOD):
            raise ValidationError(f"lod: levels must lie in 0..{MAX_LOD}; got {int(levels.min())}..{int(levels.max())}")
        self._lod[ids] = levels

    def lod_from_camera(self, camera, bands) -> np.ndarray:
        """Set every agent's level of detail from its distance to `camera` (a world point, 3) and
        `bands` (1 to MAX_LOD increasing distances): level 0 nearer than bands[0], level k from
        bands[k - 1] on. Distances are from each agent's ``placement`` (which a Driver sets every
        frame). Returns the levels (N,)."""
        eye = np.asarray(camera, dtype=np.float64) if not isinstance(camera, str) else None
        if eye is None or eye.shape != (3,) or not np.all(np.isfinite(eye)):
            raise ValidationError(f"camera must be a finite world point (x, y, z); got {camera!r}")
        edges = np.atleast_1d(np.asarray(bands, dtype=np.float64)) if not isinstance(bands, str) else None
        if (edges is None or edges.ndim != 1 or not 1 <= len(edges) <= MAX_LOD or not np.all(np.isfinite(edges))
                or edges[0] <= 0 or np.any(np.diff(edges) <= 0)):  # fmt: skip
            raise ValidationError(f"bands must be 1 to {MAX_LOD} increasing positive distances; got {bands!r}")
        distance = np.linalg.norm(self.placement[:, :3, 3] - eye, axis=1)
        levels = np.searchsorted(edges, distance, side="right").astype(np.uint8)
        self._lod[:] = levels
        return levels

    def refresh(self, out, cluster=None) -> np.ndarray:
        """Rewrite in `out` (N, J, 12) float32, a numpy store's pose buffer of every agent, the
        entries (``entries``) of the agents the last update refreshed (``due``) that have
        `cluster`, leaving the others' rows as they were: far agents' poses held between their
        refreshes, their cost paid on their frames only. Returns the ids written."""
        c = self.cluster_index(cluster if cluster is not None else self.clusters[0])
        self._check_out(out, (self.n_agents, self.skeletons[c].n_joints, ENTRY_FLOATS))
        ids = np.flatnonzero(self.due() & (self._buffer["kind"][:, c] != NONE))
        if self.overrides.get(self.clusters[c]):
            out[ids] = self.entries(ids, self.clusters[c])
        else:
            self._entries(ids, c, out=out, places=ids)
        return ids

    # -- reading --------------------------------------------------------------------------------

    def _destination(self, cluster, ids=slice(None)):
        """(kind, stream, offset) each part of `ids` in `cluster` heads for: what it blends to while
        blending, else what it reads."""
        record = self._buffer[ids, self.cluster_index(cluster)]
        blending = record["blend_time"] > 0
        kind = np.where(blending, record["target_kind"], record["kind"])
        stream = np.where(blending, record["target"], record["stream"])
        return kind, stream, np.where(blending, record["target_offset"], record["offset"]).astype(np.float64)

    def offsets(self, cluster) -> np.ndarray:
        """Each agent's offset in `cluster` (N,): of the stream it blends to while blending, else
        of the stream it reads; NaN where it has no such part or reads a unique slot."""
        kind, _, offset = self._destination(cluster)
        return np.where(kind == STREAMED, offset, np.nan)

    def synchrony(self, cluster, agents=None) -> float:
        """The share of pairs of `agents`' parts (default all) in `cluster` that read one stream
        at one offset (to the nearest frame), among the pairs that read one stream: 1 when all
        move alike (a Stopped stream just started), about 1 / history once offsets are spread."""
        ids = np.arange(self.n_agents) if agents is None else _agent_ids(agents, self.n_agents)
        kind, stream, offset = self._destination(cluster, ids)
        streamed = kind == STREAMED
        stream, frame = stream[streamed], np.rint(offset[streamed]).astype(np.int64)

        def pairs(*keys):
            counts = np.unique(np.stack(keys, axis=1), axis=0, return_counts=True)[1] if len(keys[0]) else np.zeros(0)
            return float(np.sum(counts * (counts - 1) / 2))

        together = pairs(stream)
        return pairs(stream, frame) / together if together else 0.0

    def dilation_targets(self, cluster) -> np.ndarray:
        """Each agent's time-dilation target offset in `cluster` (N,); NaN where not dilating."""
        return self._dilate_to[:, self.cluster_index(cluster)].astype(np.float64)

    def alphas(self, cluster) -> np.ndarray:
        """Each agent's blend weight α = clamp(elapsed / blend_time, 0, 1) in `cluster` (Listing
        3): 0 reads the source only; NaN where it is not blending."""
        record = self._buffer[:, self.cluster_index(cluster)]
        blending = record["blend_time"] > 0
        alpha = np.clip((self.time - record["blend_start"]) / np.where(blending, record["blend_time"], 1), 0, 1)
        return np.where(blending, alpha, np.nan)

    def _read(self, kind, index, offset, bones):
        """Entries (n, bones, 12) of parts reading (kind, stream or slot, offset), in the pool's
        array namespace. An offset between two frames (a part dilating) reads that far between
        them, slerped as a clip is between keys (`interpolate_entries`), so that a dilating part
        moves every frame rather than holding a frame while its offset catches up."""
        xp = self.pool.xp
        streamed = np.flatnonzero(kind == STREAMED)
        streams, behind = index[streamed], np.asarray(offset[streamed], dtype=np.float64)
        whole = np.floor(behind)
        taken = self.pool.gather(streams, whole.astype(np.int64), bones)
        between = np.flatnonzero(behind > whole)
        if len(between):
            older = self.pool.gather(streams[between], whole[between].astype(np.int64) + 1, bones)
            newer = xp.take(taken, xp.asarray(between), axis=0)
            moved = interpolate_entries(newer, older, xp.asarray((behind - whole)[between], dtype=xp.float32))
            if xp is np:
                taken[between] = moved
            else:
                steady = np.flatnonzero(behind <= whole)
                taken = _merge(xp, xp.take(taken, xp.asarray(steady), axis=0), steady, moved, between)
        if len(streamed) == len(kind):
            return taken
        unique = np.flatnonzero(kind == UNIQUE)
        slots = xp.asarray(self.unique.store[index[unique], :bones]) if len(unique) else taken[:0]
        return _merge(xp, taken, streamed, slots, unique)

    def entries(self, agents=None, cluster=None, *, out=None):
        """Store entries (n, J, 12) float32 of `agents` (default all) in `cluster`: sources read at
        their offsets and, while blending, mixed with their targets by α (rotations on the
        sphere), in the pool's array namespace. Agents without the cluster are refused.

        `out`, for a numpy store: a C-contiguous, writeable float32 array (n, J, 12) to write them
        into and return, as an engine reuses one pose buffer frame after frame (no new array to
        allocate and fault in)."""
        c = self.cluster_index(cluster if cluster is not None else self.clusters[0])
        ids = np.arange(self.n_agents) if agents is None else _agent_ids(agents, self.n_agents)
        if out is not None:
            self._check_out(out, (len(ids), self.skeletons[c].n_joints, ENTRY_FLOATS))
        entries = self._entries(ids, c, out=out)
        overrides = self.overrides.get(self.clusters[c], ())
        if overrides:
            if self.pool.xp is not np:
                raise ValidationError("pose overrides run on numpy: read a store on a device without them")
            skeleton = self.skeletons[c]
            origins = self._origins(ids, c)
            for override in overrides:
                joints = [skeleton.index(j) for j in override.joints]
                changed = override.apply(entries_pose(entries), skeleton=skeleton, agents=ids, origins=origins,
                                         time=self.time)  # fmt: skip
                entries[:, joints, 0:4] = np.asarray(changed.rotations)[:, joints]
                entries[:, joints, 4:7] = np.asarray(changed.translations)[:, joints]
        return entries

    def _anchors(self, ids, c) -> np.ndarray | None:
        """Where cluster `c` of agents `ids` hangs in their model space (n, 4, 4): its parent
        joint's world transform times the hook's offset; None for a cluster on no hook."""
        hook = self.hooks.get(self.clusters[c])
        if hook is None:
            return None
        p = self.cluster_index(hook.parent)
        skeleton = self.skeletons[p]
        pose = entries_pose(self.entries(ids, hook.parent))
        chain, k = [], skeleton.index(hook.joint)
        while k >= 0:  # the joint and its ancestors: forward kinematics down that chain only
            chain.insert(0, k)
            k = skeleton.parents[k]
        parent = self._anchors(ids, p)
        for k in chain:
            local = rigid.trs(pose.translations[:, k], pose.rotations[:, k], skeleton.scales[k])
            parent = local if parent is None else parent @ local
        return parent.astype(np.float64) @ hook.offset

    def _origins(self, ids, c) -> np.ndarray:
        """The world transforms (n, 4, 4) of cluster `c`'s model space for agents `ids`."""
        anchors = self._anchors(ids, c)
        return self.placement[ids] if anchors is None else self.placement[ids] @ anchors

    def _entries(self, ids, c, lag: int = 0, *, out=None, compiled: bool = True, places=None):
        """`entries` of parts `ids` in cluster index `c`, as they were `lag` frames ago (offsets
        `lag` frames older, up to the oldest frame held; α then). A numpy store is read by the
        compiled loops (`_kernels.plan_reads`, `_kernels.read_entries`), into `out` when given;
        `compiled=False`, or a store in another namespace, reads through the array API. `places`:
        the rows of `out` the parts go to (default 0..n - 1)."""
        bones = self.skeletons[c].n_joints
        then = self.time - lag / self.pool.fps
        if self.pool.xp is np and compiled:
            return self._entries_compiled(ids, c, bones, lag, then, out, places)
        record = self._buffer[ids, c]
        if np.any(record["kind"] == NONE):
            self._no_cluster(ids[record["kind"] == NONE][0], c)

        def read(kind, index, offset):
            return self._read(kind, index, self._lagged(kind, index, offset, lag), bones)

        blending = np.flatnonzero(record["blend_time"] > 0)
        if not len(blending):
            return read(record["kind"], record["stream"], record["offset"])
        xp = self.pool.xp
        steady = np.flatnonzero(record["blend_time"] <= 0)
        r = record[blending]
        target = read(r["target_kind"], r["target"], r["target_offset"])
        alpha = xp.asarray(np.clip((then - r["blend_start"]) / r["blend_time"], 0, 1).astype(np.float32))
        if xp is np:  # every source at once, the blending rows mixed in place: no merge of two reads
            out = read(record["kind"], record["stream"], record["offset"])
            out[blending] = blend_entries(out[blending], target, alpha)
            return out
        mixed = blend_entries(read(r["kind"], r["stream"], r["offset"]), target, alpha)
        if not len(steady):
            return mixed
        s = record[steady]
        return _merge(xp, read(s["kind"], s["stream"], s["offset"]), steady, mixed, blending)

    def _no_cluster(self, agent, c):
        raise ValidationError(f"agent {int(agent)} has no {self.clusters[c]!r} cluster")

    def _lagged(self, kind, index, offset, lag: int):
        """Offsets `lag` frames older, up to the oldest frame each stream holds."""
        if not lag:
            return offset
        held = np.where(kind == STREAMED, self.pool.filled[np.where(kind == STREAMED, index, 0)], 1)
        return np.minimum(offset + lag, held - 1)

    def _entries_compiled(self, ids, c, bones: int, lag: int, then: float, out, places=None):
        """`_entries` of a numpy store: what each part reads (its source, and its target while
        blending) found by `_kernels.plan_reads`, then read and mixed in one pass by
        `_kernels.read_entries` into `out` (made when None)."""
        n = len(ids)
        if out is None:
            out = np.empty((n, bones, ENTRY_FLOATS), dtype=np.float32)
        rows = np.empty((n, 4), dtype=np.int64)
        shares = np.empty((n, 2), dtype=np.float32)
        on_unique = np.empty((n, 2), dtype=np.bool_)
        alpha = np.empty(n, dtype=np.float32)
        pool = self.pool
        width = self.unique.max_bones * ENTRY_FLOATS if self.unique is not None else 0
        missing = _kernels.plan_reads(self._buffer[:, c], ids, pool.head, pool.history, pool.lookup, pool.filled,
                                      width, lag, np.float32(then), rows, shares, on_unique, alpha)  # fmt: skip
        if missing >= 0:
            self._no_cluster(ids[missing], c)
        unique = self.unique.store.reshape(-1) if self.unique is not None else np.zeros(0, dtype=np.float32)
        places = np.arange(n) if places is None else places
        _kernels.read_entries(pool.store, unique, rows, on_unique, shares, alpha, places, out)
        return out

    def poses(self, agents=None, cluster=None, *, space: str = "local", out=None):
        """The poses of `agents` (default all) in `cluster`, vectorized: ``space="local"`` a
        float32 Pose (n, J) of local rotations and translations; ``"world"`` world (model-space)
        joint matrices (n, J, 4, 4) float32 by forward kinematics: in the agent's model space
        (what ``placement`` or a Driver's roots take into the scene), a hooked cluster placed at
        its parent joint (``Hook``).

        `out` (numpy store): where to write them, reused frame after frame: for local poses the
        entries (n, J, 12) float32 the Pose views (``entries``'s `out`), for world poses the
        matrices (n, J, 4, 4) float32; C-contiguous and writeable."""
        if space not in ("local", "world"):
            raise ValidationError(f"space must be 'local' or 'world'; got {space!r}")
        if space == "local":
            return entries_pose(self.entries(agents, cluster, out=out))
        if self.pool.xp is not np:
            raise ValidationError("world poses are computed with numpy: read local poses from a store on a device")
        c = self.cluster_index(cluster if cluster is not None else self.clusters[0])
        ids = np.arange(self.n_agents) if agents is None else _agent_ids(agents, self.n_agents)
        skeleton = self.skeletons[c]
        if out is None:
            out = np.empty((len(ids), skeleton.n_joints, 4, 4), dtype=np.float32)
        else:
            self._check_out(out, (len(ids), skeleton.n_joints, 4, 4))
        entries = self.entries(ids, self.clusters[c])
        _kernels.world_matrices(entries, skeleton.parents, skeleton.scales.astype(np.float32), out)
        anchors = self._anchors(ids, c)
        if anchors is not None:
            out[:] = anchors[:, None] @ out
        return out

    def _check_out(self, out, shape) -> None:
        if self.pool.xp is not np:
            raise ValidationError("out is for a store in numpy; a store on a device returns new arrays")
        if (not isinstance(out, np.ndarray) or out.dtype != np.float32 or out.shape != shape
                or not out.flags.c_contiguous or not out.flags.writeable):  # fmt: skip
            raise ValidationError(
                f"out must be a C-contiguous, writeable float32 numpy array of shape {shape}; got "
                f"{type(out).__name__} {getattr(out, 'dtype', '')} {getattr(out, 'shape', '')}"
            )

    def instance_buffer(self) -> np.ndarray:
        """What a skinning shader needs per agent part (N, C), a structured array of INSTANCE
        records: stream, offset, target, target_offset, blend_start, blend_time, kind,
        target_kind and the agent's visibility mask. A read-only view, valid until the next
        update or transition."""
        view = self._buffer.view()
        view.setflags(write=False)
        return view

    def set_visible(self, agents, cluster, visible: bool) -> None:
        """Show or hide `agents`' part `cluster` (the shader skips hidden clusters)."""
        ids, c = self._parts(agents, cluster)
        bit = np.uint16(1 << c)
        masks = self._buffer["mask"][ids]
        self._buffer["mask"][ids] = np.where(validate.flag(visible, "visible"), masks | bit, masks & ~bit)
