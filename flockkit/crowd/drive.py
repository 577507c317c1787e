"""Crowds driven by trajectories: every agent's root on its path, facing where it goes, its body
playing the stream a speed state machine picks (paper 003 fed by papers 000 and 004).

A Motion says where each agent is; a ``StateMachine`` says which streams its body plays at which
speeds (idle below one speed, walk, run above another, with hysteresis so that an agent near a
threshold does not flicker); ``Driver`` steps a Crowd along the Motion, switching streams with a
blend. Within a state, several streams may play one clip at different rates: each agent takes the
one whose ground speed (how fast the clip's feet push back, times its rate) is nearest its own,
so that feet do not slide.
"""

from __future__ import annotations

import math
import warnings

import attrs
import numpy as np

from .. import rigid, validate
from ..errors import FlockkitWarning, ValidationError
from ..mesh import conversion_matrix, unit_hint
from ..motion import Motion
from ..skeleton import Skeleton
from .runtime import Crowd

__all__ = ["Gait", "StateMachine", "Cue", "Driver", "character_frame", "character_axes", "AXES", "DEFAULT_FORWARD"]

AXES = {"x": 0, "y": 1, "z": 2}
# The forward axis of a character whose file does not say, by its up axis: glTF's +z for a y-up
# character (glTF 2.0, section 3.4: "the front of a glTF asset faces +Z"), flockkit's +x (heading
# 0) for a z-up one, and +y (the next axis round) for an x-up one.
DEFAULT_FORWARD = {"x": "y", "y": "z", "z": "x"}

# The controller that plays one clip: a convenience default, as flockkit.build_graph's builder is;
# a crowd scene's [[streams]] entry, or driven_sliding's `controller`, names another (any
# controller declaring Capabilities(clip_player=True): it takes clip= and rate=).
CLIP_CONTROLLER = "clip"


def _streams(value) -> tuple:
    streams = tuple(int(v) for v in np.atleast_1d(np.asarray(value)))
    if not streams:
        raise ValidationError("Gait.streams must name at least one stream")
    return streams


@attrs.frozen(kw_only=True)
class Gait:
    """A gait: a state of the speed machine (idle, walk, run), the agent speeds it covers, [low, high),
    and its streams.

    Parameters
    ----------
    name : str
    streams : int or sequence of int
        Stream ids of the crowd's pool.
    speeds : sequence of float, optional
        The ground speed each stream plays without sliding (world units per second; see
        ``ground_speed``): an agent takes the stream nearest its speed. None: the first stream.
    low, high : float
        The values of this state (agent speeds, or climb rates for a machine on ``climb``); the
        states of a machine tile [0, inf) for speeds, (-inf, inf) for climb rates.
    """

    name: str = attrs.field()
    streams: tuple = attrs.field(converter=_streams)
    speeds: tuple | None = attrs.field(default=None, converter=lambda v: None if v is None else tuple(map(float, v)))
    low: float = attrs.field(default=0.0, converter=float)
    high: float = attrs.field(default=math.inf, converter=float)

    def __attrs_post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValidationError(f"Gait.name must be a non-empty string; got {self.name!r}")
        if not self.low < self.high:
            raise ValidationError(f"state {self.name!r}: needs low < high; got low {self.low}, high {self.high}")
        if self.speeds is not None and len(self.speeds) != len(self.streams):
            raise ValidationError(
                f"state {self.name!r}: {len(self.speeds)} speeds for {len(self.streams)} streams (one each)"
            )


class StateMachine:
    """States on a measure of each agent's motion, `on` "speed" (horizontal, tiling [0, inf)) or
    "climb" (vertical speed, z up, tiling (-inf, inf)), with `hysteresis` (world units per
    second): an agent leaves its state only when its value passes the state's bounds by more than
    that, so that one near a threshold does not flicker. Switches blend over `blend_time` s."""

    def __init__(self, states, *, on: str = "speed", hysteresis: float = 0.05, blend_time: float = 0.3):
        if on not in ("speed", "climb"):
            raise ValidationError(f"StateMachine on must be 'speed' or 'climb'; got {on!r}")
        self.on = on
        self.states = tuple(sorted(states, key=lambda s: s.low))
        if not self.states or not all(isinstance(s, Gait) for s in self.states):
            raise ValidationError("StateMachine needs a non-empty sequence of flockkit.crowd.Gait")
        names = [s.name for s in self.states]
        if len(set(names)) != len(names):
            raise ValidationError(f"StateMachine: state names repeat: {names}")
        bottom = 0.0 if on == "speed" else -math.inf
        if self.states[0].low > bottom:
            raise ValidationError(f"StateMachine: no state covers values below {self.states[0].low} (a gap)")
        for a, b in zip(self.states[:-1], self.states[1:]):
            if a.high > b.low:
                raise ValidationError(f"StateMachine: states {a.name!r} and {b.name!r} overlap ({b.low} < {a.high})")
            if a.high < b.low:
                raise ValidationError(
                    f"StateMachine: no state covers values {a.high}..{b.low} between {a.name!r} and {b.name!r}"
                )
        if math.isfinite(self.states[-1].high):
            raise ValidationError(f"StateMachine: no state covers values above {self.states[-1].high}")
        self.hysteresis = validate.number(hysteresis, "StateMachine.hysteresis", minimum=0)
        self.blend_time = validate.number(blend_time, "StateMachine.blend_time", minimum=0, strict=True)
        self._lows = np.array([s.low for s in self.states])
        self._highs = np.array([s.high for s in self.states])

    def choose(self, speeds: np.ndarray, current: np.ndarray | None = None) -> np.ndarray:
        """The state of each agent at `speeds`, staying in `current` (state indices, -1 none)
        while its speed is within its bounds widened by the hysteresis."""
        fresh = np.searchsorted(self._lows, speeds, side="right") - 1
        if current is None:
            return fresh
        keep = (current >= 0) & (speeds >= self._lows[current] - self.hysteresis)
        keep &= speeds < self._highs[current] + self.hysteresis
        return np.where(keep, current, fresh)

    def check(self, crowd: Crowd, cluster) -> None:
        """Every state's streams exist in `crowd`'s pool with `cluster`'s skeleton."""
        for state in self.states:
            for stream in state.streams:
                _check_stream(crowd, cluster, stream, f"state {state.name!r} names stream {stream}")


def _check_stream(crowd: Crowd, cluster, stream, owner: str) -> None:
    """`stream` is in `crowd`'s pool and has `cluster`'s skeleton; errors name `owner`."""
    (k,) = crowd.pool.check_streams(stream, field=owner)
    if not crowd.pool.streams[k].skeleton.matches(crowd.skeletons[crowd.cluster_index(cluster)]):
        raise ValidationError(f"{owner}: stream {k}'s skeleton is not cluster {cluster!r}'s")


@attrs.frozen(kw_only=True)
class Cue:
    """A scene event: at `time` seconds, `agents` switch to `stream` (blending over `blend_time`;
    into a Stopped stream with time dilation over `time_to_dilate`), for `duration` seconds (None:
    to the end), then go back to what the state machine picks ("goal at 12 s: the home
    supporters cheer for 4 s")."""

    time: float = attrs.field(converter=float)
    agents: np.ndarray = attrs.field(converter=lambda v: np.atleast_1d(np.asarray(v)))
    stream: int = attrs.field(converter=int)
    duration: float | None = attrs.field(default=None)
    blend_time: float = attrs.field(default=0.3, converter=float)
    time_to_dilate: float | None = attrs.field(default=None)
    name: str = attrs.field(default="cue")

    def __attrs_post_init__(self):
        if not math.isfinite(self.time) or self.time < 0:
            raise ValidationError(f"cue {self.name!r}: time must be a time >= 0 in seconds; got {self.time}")
        if self.duration is not None:
            validate.number(self.duration, f"cue {self.name!r}: duration", minimum=0, strict=True)
        validate.number(self.blend_time, f"cue {self.name!r}: blend_time", minimum=0, strict=True)


def _axis(name: str, field: str) -> int:
    if name not in AXES:
        raise ValidationError(f"{field} must be 'x', 'y' or 'z'; got {name!r}")
    return AXES[name]


def character_frame(up: str, forward: str) -> np.ndarray:
    """The rotation (3, 3) taking a character's axes (`up`, `forward`) to flockkit's world (z up,
    facing +x at heading 0): ``flockkit.mesh.conversion_matrix(up, 1)``, which brings the up axis
    onto +z, then the turn about +z that brings the forward axis onto +x. Its rows are forward,
    up x forward and up."""
    u, f = _axis(up, "up"), _axis(forward, "forward")
    if u == f:
        raise ValidationError("up and forward must be different axes")
    upright = conversion_matrix(up, 1.0)
    ahead = upright[:, f]  # where the forward axis points once the character stands up: on the ground
    facing = np.array([[ahead[0], ahead[1], 0.0], [-ahead[1], ahead[0], 0.0], [0.0, 0.0, 1.0]])
    return facing @ upright


def character_axes(skeleton: Skeleton, *, up=None, forward=None, scale=None, owner: str = "Driver") -> tuple:
    """(up, forward, scale) for placing `skeleton` in the world: each as given, or by default
    the skeleton's up axis, ``DEFAULT_FORWARD`` of it, and its metres per unit (flockkit's world
    is in metres). A ValidationError naming `owner` where the skeleton's unit is not known (a
    BVH file states none) and no scale is given; a FlockkitWarning with a hint
    (``flockkit.mesh.unit_hint``) where the default scale makes the character a size no
    character has (the Fox of the glTF samples, centimetres read as metres, is 61 m tall)."""
    up = skeleton.up_axis if up is None else up
    _axis(up, f"{owner} up")
    forward = DEFAULT_FORWARD[up] if forward is None else forward
    if scale is not None:
        return up, forward, validate.number(scale, f"{owner} scale", minimum=0, strict=True)
    height = _height(skeleton, up)
    if skeleton.meters_per_unit is None:
        sizes = ", ".join(f"{height * factor:.3g} m in {name}" for name, factor in (("cm", 0.01), ("in", 0.0254)))
        raise ValidationError(
            f"{owner}: the skeleton states no unit (a BVH file does not): state it with meters_per_unit (metres per "
            f"unit, or a name such as 'cm' or 'in') when reading its clips or in a crowd file's [character], or give "
            f"a scale; it stands {height:.4g} units tall ({sizes})"
        )
    hint = unit_hint(height, skeleton.meters_per_unit, "the character")
    if hint is not None:
        warnings.warn(f"{owner}: {hint}", FlockkitWarning, stacklevel=3)
    return up, forward, skeleton.meters_per_unit


def _height(skeleton: Skeleton, up: str) -> float:
    """How far the skeleton's joints spread along `up` at rest, in its units."""
    heights = skeleton.positions(skeleton.rest)[:, AXES[up]]
    return float(heights.max() - heights.min())


class Driver:
    """Step a Crowd along a Motion: root transforms on the trajectories, facing the velocity, and
    streams from a StateMachine on speed.

    Parameters
    ----------
    crowd : Crowd
    motion : Motion
        Trajectories (2D on the ground, or 3D with z up) of at least ``crowd.n_agents`` agents;
        agent k of the crowd follows agent k. Sampled at the crowd's frames by linear
        interpolation; held after its end.
    machine : StateMachine
    cluster : str, optional
        The cluster the machine drives (default the crowd's first).
    up, forward : str, optional
        The character's up and forward axes. Default: the skeleton's up axis (what its file
        says: glTF and BVH "y") and ``DEFAULT_FORWARD`` of it (glTF's "z" for y up).
    scale : float, optional
        Metres (world units: flockkit's world is in metres) per character unit. Default the
        skeleton's ``meters_per_unit`` (what its file says, or what ``read_clips`` was told: the
        Fox of the glTF samples is modelled in centimetres, 0.01); a skeleton without a unit
        (a BVH file's) needs it. Each root is then ``heading @ character_frame(up, forward) *
        scale``: the character stands along +z at its true size, its forward along its
        heading (``frame_to_world`` holds the part that does not turn).
    turn_time : float
        Seconds over which the facing follows the velocity (an exponential smoothing); an agent
        slower than `still` keeps its facing.
    cues : sequence of Cue
        Scene events; each must fall within the trajectories' time.
    root_motion : {"trajectory", "clip"}
        Where the roots go. "trajectory" (the default): on the trajectories, facing their
        velocity, the clips played in place. "clip": each agent starts where and as its
        trajectory starts, then advances by its clips' root motion (``Crowd.roots``: the crowd
        must be made with ``root_motion=`` this driver's cluster, and its streams' controllers
        offer root motion, as the clip player of a clip from ``extract_root_motion`` does); the
        trajectories still choose each agent's gait by their speed, and cues still apply.

    Attributes
    ----------
    roots : (N, 4, 4)
        Each agent's root in the world after the last step; also written to the crowd's
        ``placement``.
    """

    def __init__(self, crowd: Crowd, motion: Motion, machine: StateMachine, *, cluster=None, up=None, forward=None,
                 scale=None, turn_time: float = 0.25, still: float = 1e-3, cues=(),
                 root_motion="trajectory"):  # fmt: skip
        if not isinstance(crowd, Crowd):
            raise ValidationError(f"Driver needs a flockkit.Crowd; got {type(crowd).__name__}")
        if not isinstance(motion, Motion):
            raise ValidationError(f"Driver needs trajectories as a flockkit.Motion; got {type(motion).__name__}")
        if motion.n_agents < crowd.n_agents:
            raise ValidationError(
                f"the trajectories have {motion.n_agents} agents; the crowd has {crowd.n_agents} (one each)"
            )
        if not isinstance(machine, StateMachine):
            raise ValidationError(f"Driver needs a flockkit.crowd.StateMachine; got {type(machine).__name__}")
        self.crowd, self.motion, self.machine = crowd, motion, machine
        self.cluster = crowd.clusters[0] if cluster is None else cluster
        if root_motion not in ("trajectory", "clip"):
            raise ValidationError(f"Driver root_motion must be 'trajectory' or 'clip'; got {root_motion!r}")
        if root_motion == "clip" and crowd.root_motion != self.cluster:
            raise ValidationError(
                f"Driver root_motion='clip' moves agents by cluster {self.cluster!r}'s root motion: make the Crowd "
                f"with root_motion={self.cluster!r} (it has {crowd.root_motion!r})"
            )
        self.root_motion = root_motion
        machine.check(crowd, self.cluster)
        skeleton = crowd.skeletons[crowd.cluster_index(self.cluster)]
        self.up, self.forward, self.scale = character_axes(skeleton, up=up, forward=forward, scale=scale,
                                                           owner="Driver")  # fmt: skip
        self.turn_time = validate.number(turn_time, "Driver.turn_time", minimum=0)
        self.still = validate.number(still, "Driver.still", minimum=0)
        self.frame_to_world = character_frame(self.up, self.forward) * self.scale
        # what an export records of the conversion: the character's axes as its file gave them
        self.axes = {"up_axis": self.up, "forward_axis": self.forward, "meters_per_unit": self.scale,
                     "skeleton_meters_per_unit": skeleton.meters_per_unit}  # fmt: skip
        n = crowd.n_agents
        positions = np.zeros((motion.n_frames, n, 3))
        positions[..., : motion.dims] = motion.positions[:, :n]
        self._positions = positions
        self._velocities = (
            np.gradient(positions, motion.dt, axis=0) if motion.n_frames > 1 else np.zeros_like(positions)
        )
        self.state = np.full(n, -1)
        self.stream = np.full(n, -1)
        self.heading = np.zeros(n)
        self.roots = np.tile(np.eye(4), (n, 1, 1))
        self.switches = 0
        self.cues = tuple(cues)
        for cue in self.cues:
            if not isinstance(cue, Cue):
                raise ValidationError(f"Driver cues must be flockkit.crowd.Cue; got {type(cue).__name__}")
            if cue.time > motion.duration:
                raise ValidationError(
                    f"cue {cue.name!r} at {cue.time} s is past the trajectories' end ({motion.duration:.6g} s)"
                )
            _check_stream(crowd, self.cluster, cue.stream, f"cue {cue.name!r}")
            if cue.agents.dtype.kind not in "iu" or cue.agents.min() < 0 or cue.agents.max() >= n:
                raise ValidationError(f"cue {cue.name!r}: agents must be ids in 0..{n - 1}")
        self.pinned = np.full(n, -1)  # the cue each agent follows, -1: the state machine
        # per state with speeds, each stream's ground speed (inf: not the state's), for lookups by stream id
        self._ground = []
        for state in machine.states:
            ground = np.full(len(crowd.pool.streams), np.inf)
            if state.speeds is not None:
                ground[list(state.streams)] = state.speeds
            self._ground.append(ground)
        self._place(first=True)

    def _sample(self, array: np.ndarray, t: float) -> np.ndarray:
        f = min(max(t / self.motion.dt, 0.0), self.motion.n_frames - 1)
        k = min(int(f), self.motion.n_frames - 2) if self.motion.n_frames > 1 else 0
        u = f - k if self.motion.n_frames > 1 else 0.0
        return array[k] if self.motion.n_frames == 1 else (1 - u) * array[k] + u * array[k + 1]

    def _place(self, *, first: bool = False) -> None:
        t = self.crowd.time
        position, velocity = self._sample(self._positions, t), self._sample(self._velocities, t)
        speed = np.linalg.norm(velocity[:, :2], axis=1)
        moving = speed > self.still
        measure = speed if self.machine.on == "speed" else velocity[:, 2]
        target = np.arctan2(velocity[:, 1], velocity[:, 0])
        if self.root_motion == "clip" and not first:
            # the start, then the clips' ground motion in the character's model space (the
            # character's up axis is the world's z, so its heading adds to the start's)
            self.roots = self._start @ self.crowd.roots()
            self.heading = self._start_heading + self.crowd._ground[:, 3]
            self.crowd.placement = self.roots
            self._choose(measure, first=first)
            return
        if first:
            self.heading = np.where(moving, target, 0.0)
        else:
            share = 1.0 if self.turn_time == 0 else 1 - math.exp(-(1 / self.crowd.pool.fps) / self.turn_time)
            turn = (target - self.heading + np.pi) % (2 * np.pi) - np.pi
            self.heading = np.where(moving, self.heading + share * turn, self.heading)
        half = self.heading / 2
        zero = np.zeros_like(half)
        yaw = rigid.quaternion_matrix(np.stack([zero, zero, np.sin(half), np.cos(half)], axis=1))
        self.roots[:, :3, :3] = yaw @ self.frame_to_world
        self.roots[:, :3, 3] = position
        if first:
            self._start, self._start_heading = self.roots.copy(), self.heading.copy()
        self.crowd.placement = self.roots.copy()
        self._choose(measure, first=first)

    def _choose(self, value: np.ndarray, *, first: bool) -> None:
        state = self.machine.choose(value, None if first else self.state)
        stream = np.empty_like(self.stream)
        for k, s in enumerate(self.machine.states):
            mine = np.flatnonzero(state == k)
            if s.speeds is None:
                stream[mine] = s.streams[0]
            else:
                nearest = np.argmin(np.abs(value[mine, None] - np.asarray(s.speeds)[None]), axis=1)
                chosen = np.asarray(s.streams)[nearest]
                # keep the current stream of the state while its value is nearly as good
                current = self.stream[mine]
                now = np.where(current >= 0, self._ground[k][current], np.inf)
                best = np.asarray(s.speeds)[nearest]
                kept = np.isfinite(now) & (state[mine] == self.state[mine])
                kept &= np.abs(value[mine] - now) <= np.abs(value[mine] - best) + self.machine.hysteresis
                stream[mine] = np.where(kept, current, chosen)
        if first:
            for s in np.unique(stream):
                self.crowd.assign(np.flatnonzero(stream == s), self.cluster, int(s))
        else:
            free = self.pinned < 0
            stream = np.where(free, stream, self.stream)
            state = np.where(free, state, self.state)
            for s in np.unique(stream):
                group = np.flatnonzero((stream == s) & (stream != self.stream))
                if not len(group):
                    continue
                # a switch of rate within a state keeps each agent's step; a change of state
                # enters at random offsets (agents that look alike would all match one frame)
                same = group[(state[group] == self.state[group]) & self.crowd.pool.running[s]]
                if len(same):
                    offsets = self.crowd.matching_offsets(same, self.cluster, int(s))
                    self.crowd.transition_to_streamed(
                        same, self.cluster, int(s), self.machine.blend_time, offsets=offsets
                    )
                other = np.setdiff1d(group, same)
                if len(other):
                    self.crowd.transition_to_streamed(other, self.cluster, int(s), self.machine.blend_time)
                self.switches += len(group)
        self.state, self.stream = state, stream

    def step(self) -> list:
        """One frame: the crowd updates, then roots and streams follow the trajectories at the
        crowd's new time, and cues start or end. Returns the crowd's events."""
        events = self.crowd.update()
        self._place()
        self._cue()
        return events

    def _cue(self) -> None:
        now, half = self.crowd.time, 0.5 / self.crowd.pool.fps
        for k, cue in enumerate(self.cues):
            if abs(now - cue.time) <= half:
                self.crowd.transition_to_streamed(cue.agents, self.cluster, cue.stream, cue.blend_time,
                                                  time_to_dilate=cue.time_to_dilate)  # fmt: skip
                self.pinned[cue.agents] = k
                self.stream[cue.agents] = cue.stream
            elif cue.duration is not None and abs(now - cue.time - cue.duration) <= half:
                self.pinned[cue.agents[self.pinned[cue.agents] == k]] = -1

    def world(self, agents=None, cluster=None) -> np.ndarray:
        """World joint matrices (n, J, 4, 4) of `agents` (default all) in `cluster` (default the
        driver's): each root times its pose (a hooked cluster where its hook places it)."""
        ids = np.arange(self.crowd.n_agents) if agents is None else np.asarray(agents)
        cluster = self.cluster if cluster is None else cluster
        poses = self.crowd.poses(ids, cluster, space="world").astype(np.float64)
        return self.roots[ids][:, None] @ poses
