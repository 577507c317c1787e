"""The built-in controllers (paper 003, section 3.4): a clip, a blend of two children (Equation 2),
children combined by blend masks (Equation 3), and an endless walk through a motion graph of a
clip (paper 000's synthesis feeding the crowd)."""

from __future__ import annotations

import math

import attrs
import numpy as np
from numba.typed import List

import flockkit
from flockkit import validate
from flockkit.crowd import Event, Pose, SkeletalClip, stream_times
from flockkit.errors import ValidationError

from ._kernels import write_frames

# Skeletal poses are 3D.
SKELETAL = flockkit.Capabilities(dims=(3,))


def _clip(value):
    if not isinstance(value, SkeletalClip):
        raise ValidationError(f"controller parameter clip must be a flockkit.SkeletalClip; got {type(value).__name__}")
    return value


def _controller(value, field: str):
    """`value` as a child controller: an instance honouring the Controller protocol."""
    try:
        return flockkit.resolve("controller", value)
    except ValidationError as exc:
        raise ValidationError(f"controller parameter {field}: {exc}") from None


def _same_skeleton(children, owner: str):
    first = children[0].skeleton
    for k, child in enumerate(children[1:], 1):
        if not first.matches(child.skeleton):
            raise ValidationError(
                f"{owner}: child {k}'s skeleton ({child.skeleton.n_joints} joints) does not match child 0's "
                f"({first.n_joints} joints): a controller combines poses of one skeleton"
            )


@attrs.frozen(kw_only=True)
class ClipPlayer:
    """Plays `clip` from `start` seconds into it, at `rate` times its speed, looping (`loop`) or
    holding its last pose. Its root motion is the clip's ``root_motion`` played alike (each loop
    adds the clip's), none for a clip without one."""

    # takes clip and rate; offers root_motion(times) and batch(controllers)
    capabilities = flockkit.Capabilities(dims=(3,), clip_player=True, root_motion=True, batch=True)

    clip: SkeletalClip = attrs.field(converter=_clip)
    loop: bool = validate.parameter("clip", default=True, kind="flag")
    rate: float = validate.parameter("clip", default=1.0, minimum=0, strict=True)
    start: float = validate.parameter("clip", default=0.0, minimum=0)

    @property
    def skeleton(self) -> flockkit.Skeleton:
        return self.clip.skeleton

    def _unwrapped(self, t):
        return self.start + self.rate * np.asarray(t, dtype=np.float64)

    def pose(self, times) -> Pose:
        u = self._unwrapped(stream_times(times, owner="clip"))
        period = self.clip.duration
        return self.clip.sample(np.mod(u, period) if self.loop and period > 0 else u)

    def batch(self, controllers) -> ClipBatch:
        """One evaluator of many clip players (``Capabilities.batch``)."""
        return ClipBatch(controllers)

    def root_motion(self, times) -> np.ndarray:
        t = stream_times(times, owner="clip")
        if self.clip.root_motion is None:
            return np.zeros((len(t), 4))
        return self.clip.root_motion.played(t, start=self.start, rate=self.rate, loop=self.loop)

    def events(self, start: float, stop: float) -> list[Event]:
        low, high = float(self._unwrapped(start)), float(self._unwrapped(stop))
        period = self.clip.duration
        if not self.loop or period <= 0:
            found = [(e.time, e.name) for e in self.clip.events if low <= e.time < high]
        elif not self.clip.events:
            found = []
        else:
            first, last = math.floor(low / period), math.floor(high / period)
            validate.allocation((last - first + 1) * len(self.clip.events),
                                f"clip: the events of {high - low:g} s of a {period:g} s loop")  # fmt: skip
            # an event at the very end is the next loop's start
            at = np.arange(first, last + 1)[:, None] * period + np.array([e.time % period for e in self.clip.events])
            names = np.broadcast_to(np.array([e.name for e in self.clip.events], dtype=object), at.shape)
            inside = (low <= at) & (at < high)
            found = list(zip(at[inside].tolist(), names[inside].tolist()))
        return [Event(time=(at - self.start) / self.rate, name=name) for at, name in sorted(found)]


class ClipBatch:
    """Clip players evaluated together by a compiled loop that writes each pose straight into the
    caller's array: the clips' keys read where the clips hold them, and each interval's slerp
    angle and its sine (signed by the side the next key is turned to) worked out once, as the
    clip's own keys do (16 bytes a joint and frame). Players of clips of channels are evaluated
    one by one through ``pose``."""

    def __init__(self, players):
        self.players = tuple(players)
        joints = {p.skeleton.n_joints for p in self.players}
        if not self.players or len(joints) != 1 or not all(isinstance(p, ClipPlayer) for p in self.players):
            raise ValidationError("clip: batch needs clip players of one joint count")
        clips, angles, sines, first, index = [], [], [], [], {}
        for p in self.players:
            clip = p.clip
            if clip.channels or id(clip) in index:
                continue
            index[id(clip)] = len(clips)
            clips.append(clip)
            first.append(sum(len(a) for a in angles))
            q = clip.rotations
            dot = np.sum(q[:-1] * q[1:], axis=-1, keepdims=True)  # as flockkit.skeleton's LINEAR keys
            angle = np.maximum(np.arccos(np.minimum(np.abs(dot), 1.0)), 1e-12)[..., 0]
            sine = np.where(dot[..., 0] < 0, -1.0, 1.0) * np.sin(angle)
            held = np.full((1, q.shape[1]), 1e-12)  # after the last key (and a clip of one frame)
            angles.append(np.concatenate([angle, held]))
            sines.append(np.concatenate([sine, np.sin(held)]))
        self._clips = List([c.rotations for c in clips]) if clips else None
        self._translations = List([c.translations for c in clips]) if clips else None
        self._angles = np.concatenate(angles) if clips else None
        self._sines = np.concatenate(sines) if clips else None
        self._framed = np.array([id(p.clip) in index for p in self.players])
        self._clip = np.array([index.get(id(p.clip), 0) for p in self.players], dtype=np.int64)
        self._first = np.array([first[k] if first else 0 for k in self._clip], dtype=np.int64)
        self._frames = np.array([p.clip.n_frames if f else 1 for p, f in zip(self.players, self._framed)])
        self._fps = np.array([p.clip.fps or 1.0 for p in self.players], dtype=np.float64)
        self._start = np.array([p.start for p in self.players], dtype=np.float64)
        self._rate = np.array([p.rate for p in self.players], dtype=np.float64)
        self._period = np.array([p.clip.duration if p.loop else 0.0 for p in self.players], dtype=np.float64)
        self._end = (self._frames - 1) / self._fps  # the last key's time, as the clip computes it
        held = (self._angles, self._sines, self._framed, self._clip, self._first, self._frames, self._fps,
                self._start, self._rate, self._period, self._end)  # fmt: skip
        self.nbytes = sum(a.nbytes for a in held if a is not None)

    def write(self, index, times, out, rows, stride) -> None:
        """``BatchedController``: the pose of player index[i] at times[i] into `out` at rows[i]."""
        index, t = np.asarray(index, dtype=np.int64), np.asarray(times, dtype=np.float64)
        rows = np.asarray(rows, dtype=np.int64)
        framed = self._framed[index]
        if not framed.all():
            for i in np.flatnonzero(~framed).tolist():
                pose = self.players[index[i]].pose(t[i : i + 1])
                j = pose.n_joints
                block = out[rows[i] : rows[i] + stride * j].reshape(j, stride)
                block[:, 0:4], block[:, 4:7] = pose.rotations[0], pose.translations[0]
            index, t, rows = index[framed], t[framed], rows[framed]
        if not len(index):
            return
        # as ClipPlayer.pose: the time on the clip, wrapped round a loop
        u = self._start[index] + self._rate[index] * t
        period = self._period[index]
        looped = period > 0
        u = np.where(looped, np.mod(u, np.where(looped, period, 1.0)), u)
        # as the clip's keys: the last key at or before it (searchsorted's), the last interval at
        # the very end; key k is at k / fps
        frames, fps = self._frames[index], self._fps[index]
        at = np.minimum(np.maximum(u, 0.0), self._end[index])
        k = np.clip(np.floor(at * fps).astype(np.int64), 0, frames - 1)
        k = np.where((k + 1 < frames) & ((k + 1) / fps <= at), k + 1, k)
        k = np.where(k / fps > at, k - 1, k)
        single = frames < 2
        k = np.where(single, 0, np.minimum(k, frames - 2))
        span = (k + 1) / fps - k / fps
        share = np.where(single, 0.0, (at - k / fps) / np.where(single, 1.0, span))
        write_frames(rows, self._clip[index], k, self._first[index] + k, share, self._clips, self._translations,
                     self._angles, self._sines, out, stride)  # fmt: skip


def _weight(value):
    """A number in [0, 1], or (time, weight) keyframes: an array (K, 2), times increasing."""
    array = np.asarray(value, dtype=np.float64) if not isinstance(value, bool) else None
    if array is None or not (array.ndim == 0 or (array.ndim == 2 and array.shape[1] == 2 and len(array))):
        raise ValidationError(f"blend parameter weight must be a number or (time, weight) keyframes; got {value!r}")
    weights = array if array.ndim == 0 else array[:, 1]
    if not np.all(np.isfinite(array)) or np.any(weights < 0) or np.any(weights > 1):
        raise ValidationError(f"blend parameter weight must lie in [0, 1] (0: child a, 1: child b); got {value!r}")
    if array.ndim == 2 and np.any(np.diff(array[:, 0]) <= 0):
        raise ValidationError("blend parameter weight: keyframe times must increase")
    array.setflags(write=False)
    return array


@attrs.frozen(kw_only=True, eq=False)
class Blend:
    """Equation 2: a + (b - a) s with rotations on the sphere, `weight` s constant or keyframed
    over the stream's time (linear between keys, held outside). Events: both children's."""

    capabilities = SKELETAL

    a = attrs.field(converter=lambda v: _controller(v, "a"))
    b = attrs.field(converter=lambda v: _controller(v, "b"))
    weight: np.ndarray = attrs.field(default=0.5, converter=_weight)

    def __attrs_post_init__(self):
        _same_skeleton([self.a, self.b], "blend")

    @property
    def skeleton(self) -> flockkit.Skeleton:
        return self.a.skeleton

    def pose(self, times) -> Pose:
        t = stream_times(times, owner="blend")
        if self.weight.ndim == 0:
            s = np.full(len(t), float(self.weight))
        else:
            s = np.interp(t, self.weight[:, 0], self.weight[:, 1])
        return Pose.blend(self.a.pose(t), self.b.pose(t), s)

    def events(self, start: float, stop: float) -> list[Event]:
        return sorted(self.a.events(start, stop) + self.b.events(start, stop), key=lambda e: e.time)


@attrs.frozen(kw_only=True, eq=False)
class Mask:
    """Equation 3: each joint's pose from the one child whose blend mask holds it. `masks` are
    one per child: a (J,) array of 0/1, or a joint name (that joint and every joint below it);
    together they must hold every joint exactly once. Events: every child's."""

    capabilities = SKELETAL

    children: tuple = attrs.field(converter=tuple)
    masks: tuple = attrs.field(converter=tuple)
    _owner: np.ndarray = attrs.field(init=False, repr=False)

    def __attrs_post_init__(self):
        if len(self.children) < 1 or len(self.children) != len(self.masks):
            raise ValidationError(
                f"mask needs one mask per child; got {len(self.children)} children and {len(self.masks)} masks"
            )
        for k, child in enumerate(self.children):
            _controller(child, f"children[{k}]")
        _same_skeleton(self.children, "mask")
        skeleton = self.skeleton
        held = np.stack([self._mask(m, k, skeleton) for k, m in enumerate(self.masks)])
        counts = held.sum(axis=0)
        if np.any(counts != 1):
            j = int(np.argmax(counts != 1))
            raise ValidationError(
                f"mask: joint {skeleton.names[j]!r} is held by {int(counts[j])} masks; each joint must be held by one"
            )
        object.__setattr__(self, "_owner", np.argmax(held, axis=0))

    @staticmethod
    def _mask(value, k, skeleton) -> np.ndarray:
        if isinstance(value, str):
            return skeleton.descendants(value)
        array = np.asarray(value)
        if array.shape != (skeleton.n_joints,) or not np.isin(array, (0, 1)).all():
            raise ValidationError(
                f"mask parameter masks[{k}] must be {skeleton.n_joints} values of 0 or 1, or a joint name"
            )
        return array.astype(bool)

    @property
    def skeleton(self) -> flockkit.Skeleton:
        return self.children[0].skeleton

    def pose(self, times) -> Pose:
        t = stream_times(times, owner="mask")
        poses = [child.pose(t) for child in self.children]
        rotations, translations = poses[0].rotations.copy(), poses[0].translations.copy()
        for k, pose in enumerate(poses[1:], 1):
            joints = self._owner == k
            rotations[:, joints] = pose.rotations[:, joints]
            translations[:, joints] = pose.translations[:, joints]
        return Pose._adopt(rotations, translations)

    def events(self, start: float, stop: float) -> list[Event]:
        return sorted((e for child in self.children for e in child.events(start, stop)), key=lambda e: e.time)


@attrs.define(kw_only=True, eq=False)
class GraphWalk:
    """An endless stream that never plays the same loop twice: a random walk through a motion
    graph of `clip`, built by `builder` (default paper 002's ``windowed``, for motion in place)
    over the joints' positions relative to the root (the clip's frames at its `fps`), blended
    across each transition as synthesize blends, and between frames slerped as a clip is between
    keys. The walk grows as later times are asked for, always the same under `seed`.
    Events: the clip's, where the walk plays through them."""

    capabilities = SKELETAL

    clip: SkeletalClip = attrs.field(converter=_clip)
    seed: int = validate.parameter("graph-walk", default=0, kind="integer", minimum=0)
    builder: object = attrs.field(default="windowed")
    graph: flockkit.MotionGraph = attrs.field(init=False, repr=False)
    _walk: dict = attrs.field(init=False, repr=False, factory=dict)

    def __attrs_post_init__(self):
        positions = self.clip.skeleton.positions(Pose._adopt(self.clip.rotations, self.clip.translations))
        roots = np.flatnonzero(self.clip.skeleton.parents < 0)
        relative = positions - positions[:, roots].mean(axis=1, keepdims=True)
        motion = flockkit.Motion(positions=relative, dt=1.0 / self.clip.fps)
        self.graph = flockkit.build_graph(motion, builder=self.builder, seed=self.seed)
        rng = np.random.default_rng(self.seed)
        self._walk.update(rng=rng, node=int(rng.integers(len(self.graph.nodes))), edges=[], since=math.inf, frames=None)
        self._walk["start"] = self._walk["node"]

    @property
    def skeleton(self) -> flockkit.Skeleton:
        return self.clip.skeleton

    def _frames(self, needed: int):
        """(frames blended into, frames blended out of, weights) of at least `needed` output frames."""
        state = self._walk
        while state["frames"] is None or len(state["frames"][0]) < needed:
            played = 0 if state["frames"] is None else len(state["frames"][0])
            target = max(needed, 2 * played, int(self.clip.fps * 10))
            while played < target:
                options = self.graph.allowed_edges(state["node"], state["since"])
                edge = options[int(state["rng"].integers(len(options)))]
                state["edges"].append(edge)
                frames = self.graph.clips[edge[1]].n_frames - 1 if edge[0] == "clip" else 0
                played += frames
                state["since"] = state["since"] + frames if edge[0] == "clip" else 0
                state["node"] = self.graph.edge_target(edge)
            walk = flockkit.Walk(start=state["start"], edges=state["edges"])
            state["frames"] = flockkit.graphs.blended_frames(self.graph, walk)
        return state["frames"]

    def _output(self, index: np.ndarray) -> Pose:
        into, out_of, weight = (a[index] for a in self._frames(int(index.max()) + 1))
        old = Pose._adopt(self.clip.rotations[out_of], self.clip.translations[out_of])
        new = Pose._adopt(self.clip.rotations[into], self.clip.translations[into])
        return Pose.blend(old, new, weight)

    def pose(self, times) -> Pose:
        f = stream_times(times, owner="graph-walk") * self.clip.fps
        if len(f) == 0:
            return Pose._adopt(np.zeros((0, self.skeleton.n_joints, 4)), np.zeros((0, self.skeleton.n_joints, 3)))
        k = np.floor(f).astype(np.int64)
        return Pose.interpolate(self._output(k), self._output(k + 1), f - k)

    def events(self, start: float, stop: float) -> list[Event]:
        if not self.clip.events or stop <= start:
            return []
        fps = self.clip.fps
        first, last = int(math.floor(start * fps)), int(math.floor(stop * fps))
        into = self._frames(last + 2)[0]
        found = []
        for i in range(max(first, 0), last + 1):
            if into[i + 1] != into[i] + 1:
                continue  # a transition: the frames between are not played
            for e in self.clip.events:
                at = (i + e.time * fps - into[i]) / fps
                if into[i] <= e.time * fps < into[i] + 1 and start <= at < stop:
                    found.append(Event(time=at, name=e.name))
        return found


def _clips(value) -> tuple:
    clips = tuple(value)
    if not clips or not all(isinstance(c, SkeletalClip) for c in clips):
        raise ValidationError("locomotion parameter clips must be one or more flockkit.SkeletalClip")
    _same_skeleton([ClipPlayer(clip=c) for c in clips], "locomotion")
    return clips


def _speeds(value) -> np.ndarray:
    speeds = np.asarray(value, dtype=np.float64)
    if speeds.ndim != 1 or not np.all(np.isfinite(speeds)) or np.any(speeds < 0) or np.any(np.diff(speeds) <= 0):
        raise ValidationError(f"locomotion parameter speeds must be increasing ground speeds >= 0; got {value!r}")
    speeds.setflags(write=False)
    return speeds


@attrs.define(kw_only=True, eq=False)
class Locomotion:
    """A state machine fed each frame (``Capabilities.live``): `clips` of one skeleton (idle,
    walk, run, ...) each moving at its ground speed in `speeds` (units a second, increasing),
    blended by the fed ``speed`` (the two clips either side, linearly in speed; held beyond the
    ends), all played at one phase that advances at the blended clips' cycle rate, so that feet
    stay in step through the blend; the fed ``turn`` (radians a second about the skeleton's up
    axis) turns the root joints `lean` seconds' worth into the turn (at most `max_turn`
    radians). Inputs start at 0 (the first clip, not turning). Its state advances from the
    time it was last asked to the time asked; an earlier time holds it. No events."""

    capabilities = flockkit.Capabilities(dims=(3,), live=True)
    inputs = {"speed": (0.0, math.inf), "turn": (-math.inf, math.inf)}  # noqa: RUF012 - the protocol's mapping

    clips: tuple = attrs.field(converter=_clips)
    speeds: np.ndarray = attrs.field(converter=_speeds, eq=False)
    lean: float = validate.parameter("locomotion", default=0.2, minimum=0)
    max_turn: float = validate.parameter("locomotion", default=0.5, minimum=0, maximum=math.pi)
    _state: dict = attrs.field(init=False, factory=dict, repr=False)

    def __attrs_post_init__(self):
        if len(self.speeds) != len(self.clips):
            raise ValidationError(f"locomotion: {len(self.clips)} clips need {len(self.clips)} speeds; got "
                                  f"{len(self.speeds)}")  # fmt: skip
        self._state.update(speed=0.0, turn=0.0, phase=0.0, time=0.0)

    @property
    def skeleton(self) -> flockkit.Skeleton:
        return self.clips[0].skeleton

    def feed(self, **values) -> None:
        """Set inputs (``speed``, ``turn``); the next ``pose`` shows them."""
        for name, value in values.items():
            if name not in self.inputs:
                raise ValidationError(f"locomotion: unknown input {name!r}; its inputs are speed and turn")
            low, high = self.inputs[name]
            value = validate.number(value, f"locomotion input {name}", minimum=low)
            if not math.isfinite(value) or value > high:
                raise ValidationError(f"locomotion input {name} must be finite and at most {high}; got {value!r}")
            self._state[name] = value

    def _mix(self) -> tuple[int, int, float]:
        """The two clips either side of the fed speed and the weight of the second."""
        speed, speeds = self._state["speed"], self.speeds
        b = int(np.clip(np.searchsorted(speeds, speed, side="right"), 1, max(len(speeds) - 1, 1)))
        a = b - 1 if len(speeds) > 1 else 0
        b = min(b, len(speeds) - 1)
        weight = 0.0 if a == b else float(np.clip((speed - speeds[a]) / (speeds[b] - speeds[a]), 0, 1))
        return a, b, weight

    def pose(self, times) -> Pose:
        t = stream_times(times, owner="locomotion")
        state = self._state
        a, b, weight = self._mix()
        durations = [max(self.clips[k].duration, 1e-9) for k in (a, b)]
        rate = (1 - weight) / durations[0] + weight / durations[1]  # cycles a second
        phase = state["phase"] + np.maximum(t - state["time"], 0.0) * rate
        if len(t):
            latest = int(np.argmax(t))
            if t[latest] > state["time"]:
                state["phase"], state["time"] = float(phase[latest] % 1.0), float(t[latest])
        cycle = np.mod(phase, 1.0)
        pose = Pose.blend(self.clips[a].sample(cycle * durations[0]), self.clips[b].sample(cycle * durations[1]),
                          np.full(len(t), weight))  # fmt: skip
        angle = float(np.clip(self.lean * state["turn"], -self.max_turn, self.max_turn))
        if angle == 0.0:
            return pose
        up = np.zeros(3)
        up["xyz".index(self.skeleton.up_axis)] = 1.0
        turn = np.append(math.sin(angle / 2) * up, math.cos(angle / 2))
        roots = np.flatnonzero(self.skeleton.parents < 0)
        rotations = pose.rotations.copy()
        rotations[:, roots] = flockkit.rigid.quaternion_product(turn, rotations[:, roots])
        return Pose._adopt(rotations, pose.translations)

    def events(self, start: float, stop: float) -> list[Event]:
        return []
