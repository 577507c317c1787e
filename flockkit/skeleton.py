"""Skeletons, poses and clips (paper 003, sections 3.1 and 3.4): the value types of skeletal
animation (what ``flockkit.io.read_clips`` reads from glTF skins and BVH, and the crowd runtime
plays), and forward kinematics vectorized over frames and over many poses at once.

A pose gives every joint a local transform relative to its parent: a rotation (a unit quaternion
x, y, z, w) and a translation; scales are the skeleton's, fixed at rest (clips do not animate
them). World (model-space) transforms are 4 x 4 matrices ``parent world @ T R S``, as a glTF viewer
composes its nodes.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from . import rigid, validate
from ._arrays import readonly_float, readonly_int
from .errors import ValidationError
from .mesh import FLOCKKIT_METERS_PER_UNIT, FLOCKKIT_UP_AXIS, check_meters_per_unit, check_up_axis

__all__ = [
    "Pose",
    "Skeleton",
    "SkeletalClip",
    "Channel",
    "Event",
    "RootMotion",
    "extract_root_motion",
    "carries_root_motion",
    "sample_keys",
    "stream_times",
    "INTERPOLATIONS",
    "ROOT_MOTION_TOLERANCE",
    "ROOT_TURN_TOLERANCE",
]

# Quaternions whose length is this close to 1 are normalized (file formats store float32 and
# round); farther ones are refused, since they are not rotations somebody meant.
UNIT_TOLERANCE = 1e-3


def unit_quaternions(value, *, field: str) -> np.ndarray:
    """`value` (..., 4) as read-only unit quaternions: normalized where within UNIT_TOLERANCE of
    length 1, else a ValidationError naming `field` and the worst length."""
    q = readonly_float(value, field=field)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValidationError(f"{field} must be quaternions (..., 4) as x, y, z, w; got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValidationError(f"{field} must be finite")
    length = np.linalg.norm(q, axis=-1)
    if length.size and np.abs(length - 1).max() > UNIT_TOLERANCE:
        worst = np.unravel_index(np.argmax(np.abs(length - 1)), length.shape)
        raise ValidationError(
            f"{field} must be unit quaternions (length 1 within {UNIT_TOLERANCE}); "
            f"entry {tuple(int(i) for i in worst)} has length {length[worst]:.6g}"
        )
    q = q / length[..., None]
    q.setflags(write=False)
    return q


def stream_times(times, *, owner: str) -> np.ndarray:
    """`times` as a 1D float array of finite seconds >= 0 on a stream's clock (a number counts as
    one time), or a ValidationError naming `owner`: what every controller's ``pose`` accepts."""
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if t.ndim != 1:
        raise ValidationError(f"{owner}.pose needs a 1D array of times in seconds; got shape {t.shape}")
    if not np.all(np.isfinite(t)) or (len(t) and t.min() < 0):
        raise ValidationError(f"{owner}.pose needs finite times >= 0 (seconds on the stream's clock)")
    return t


def _finite(value, *, field: str, shape_tail: tuple) -> np.ndarray:
    array = readonly_float(value, field=field)
    if array.shape[array.ndim - len(shape_tail) :] != shape_tail or array.ndim < len(shape_tail):
        raise ValidationError(f"{field} must have shape (..., {', '.join(map(str, shape_tail))}); got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValidationError(f"{field} must be finite")
    return array


@attrs.frozen(kw_only=True, eq=False)
class Pose:
    """Local joint transforms: `rotations` (..., J, 4) unit quaternions (x, y, z, w) and
    `translations` (..., J, 3), with any leading axes (frames, agents)."""

    rotations: np.ndarray = attrs.field(converter=lambda v: unit_quaternions(v, field="Pose.rotations"))
    translations: np.ndarray = attrs.field(converter=lambda v: _finite(v, field="Pose.translations", shape_tail=(3,)))

    def __attrs_post_init__(self):
        if self.rotations.ndim < 2 or self.translations.shape[:-1] != self.rotations.shape[:-1]:
            raise ValidationError(
                f"Pose.translations {self.translations.shape} must match Pose.rotations {self.rotations.shape} "
                "(..., J) but for the last axis"
            )

    @property
    def n_joints(self) -> int:
        """J, the number of joints."""
        return self.rotations.shape[-2]

    @property
    def shape(self) -> tuple:
        """The leading axes (frames, agents, ...)."""
        return self.rotations.shape[:-2]

    def __getitem__(self, index) -> Pose:
        """The poses at `index` of the leading axes."""
        if not self.shape:
            raise ValidationError("a single Pose has no leading axis to index")
        return Pose._adopt(self.rotations[index], self.translations[index])

    def __eq__(self, other):
        return (
            isinstance(other, Pose)
            and np.array_equal(self.rotations, other.rotations)
            and np.array_equal(self.translations, other.translations)
        )

    __hash__ = None

    @classmethod
    def _adopt(cls, rotations: np.ndarray, translations: np.ndarray) -> Pose:
        """A Pose of arrays flockkit just computed from valid poses (unit, finite, matching): no
        checks or copies, since poses are made every frame for thousands of agents."""
        pose = object.__new__(cls)
        object.__setattr__(pose, "rotations", rotations)
        object.__setattr__(pose, "translations", translations)
        return pose

    @staticmethod
    def blend(a: Pose, b: Pose, weight) -> Pose:
        """Equation 2 of paper 003: a + (b - a) s, rotations on the sphere (nlerp, the shorter way
        round); `weight` broadcasts against the leading axes (0: `a`, 1: `b`)."""
        s = np.asarray(weight, dtype=np.float64)[..., None, None]
        rotations = rigid.nlerp(a.rotations, b.rotations, s)
        return Pose._adopt(rotations, a.translations + s * (b.translations - a.translations))

    @staticmethod
    def interpolate(a: Pose, b: Pose, weight) -> Pose:
        """The pose `weight` of the way from key `a` to key `b`, as a clip moves between two keys:
        rotations slerped (the shorter way round, at a steady angular speed however far apart),
        translations linearly; `weight` broadcasts against the leading axes (0: `a`, 1: `b`)."""
        s = np.asarray(weight, dtype=np.float64)[..., None, None]
        rotations = rigid.slerp(a.rotations, b.rotations, s)
        return Pose._adopt(rotations, (1 - s) * a.translations + s * b.translations)


def _parents(value) -> np.ndarray:
    parents = readonly_int(value, field="Skeleton.parents")
    if parents.ndim != 1 or len(parents) == 0:
        raise ValidationError(f"Skeleton.parents must be a non-empty 1D array; got shape {parents.shape}")
    bad = np.flatnonzero((parents < -1) | (parents >= np.arange(len(parents))))
    if len(bad):
        j = int(bad[0])
        raise ValidationError(
            f"Skeleton.parents[{j}] = {int(parents[j])}: each joint's parent must come before it (or be -1 for a root)"
        )
    return parents


@attrs.frozen(kw_only=True, eq=False)
class Skeleton:
    """Joints in an order where every parent comes before its children.

    Parameters
    ----------
    names : sequence of str
        Unique joint names.
    parents : (J,) int
        Each joint's parent index, -1 for a root.
    rest : Pose, optional
        The rest (bind) local transforms, a Pose of shape (J, ...) without leading axes; default
        identity rotations and zero translations. A clip that does not animate a joint's
        translation keeps its rest translation.
    scales : (J, 3), optional
        Each joint's local scale (default 1): fixed, since clips do not animate scale.
    up_axis : str
        The axis ("x", "y" or "z") that points up in the skeleton's model space: z (flockkit's)
        unless its file says otherwise (glTF and BVH: y).
    meters_per_unit : float or None
        Metres per unit of its translations: 1 unless its file says otherwise; None where no one
        has stated it (a BVH file states no unit). A crowd places the skeleton in the world with
        ``flockkit.mesh.conversion_matrix`` of these two.

    Attributes
    ----------
    depth : (J,) int
        Each joint's number of ancestors (0 for a root), computed on construction.
    """

    names: tuple = attrs.field(converter=tuple)
    parents: np.ndarray = attrs.field(converter=_parents)
    rest: Pose | None = attrs.field(default=None)
    scales: np.ndarray | None = attrs.field(default=None)
    up_axis: str = attrs.field(default=FLOCKKIT_UP_AXIS, converter=lambda v: check_up_axis(v, "Skeleton.up_axis"))
    meters_per_unit: float | None = attrs.field(
        default=FLOCKKIT_METERS_PER_UNIT,
        converter=lambda v: check_meters_per_unit(v, "Skeleton.meters_per_unit", optional=True),
    )
    depth: np.ndarray = attrs.field(init=False, repr=False)

    def __attrs_post_init__(self):
        j = len(self.parents)
        if len(self.names) != j or not all(isinstance(n, str) and n for n in self.names):
            raise ValidationError(f"Skeleton.names must be {j} non-empty strings, one per joint; got {len(self.names)}")
        if len(set(self.names)) != j:
            twice = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ValidationError(f"Skeleton.names must be unique; {', '.join(map(repr, twice))} appear twice")
        rest = self.rest
        if rest is None:
            rest = Pose._adopt(np.tile([0.0, 0.0, 0.0, 1.0], (j, 1)), np.zeros((j, 3)))
        if not isinstance(rest, Pose) or rest.shape != () or rest.n_joints != j:
            raise ValidationError(f"Skeleton.rest must be a Pose of {j} joints without leading axes")
        scales = (
            np.ones((j, 3)) if self.scales is None else _finite(self.scales, field="Skeleton.scales", shape_tail=(3,))
        )
        if scales.shape != (j, 3):
            raise ValidationError(f"Skeleton.scales must have shape ({j}, 3); got {scales.shape}")
        scales.setflags(write=False)
        depth = np.zeros(j, dtype=np.int64)
        for k in range(j):
            depth[k] = 0 if self.parents[k] < 0 else depth[self.parents[k]] + 1
        depth.setflags(write=False)
        object.__setattr__(self, "rest", rest)
        object.__setattr__(self, "scales", scales)
        object.__setattr__(self, "depth", depth)

    @property
    def n_joints(self) -> int:
        """J, the number of joints."""
        return len(self.parents)

    def index(self, name: str) -> int:
        """The index of the joint called `name` (a ValidationError listing near names if none)."""
        if name not in self.names:
            import difflib

            near = difflib.get_close_matches(str(name), self.names, n=3)
            hint = f"; did you mean {', '.join(map(repr, near))}?" if near else ""
            raise ValidationError(f"the skeleton has no joint {name!r}{hint}")
        return self.names.index(name)

    def descendants(self, name: str) -> np.ndarray:
        """A mask (J,) of joint `name` and every joint below it: a blend mask for a limb."""
        mask = np.zeros(self.n_joints, dtype=bool)
        mask[self.index(name)] = True
        for k in range(self.n_joints):
            if self.parents[k] >= 0 and mask[self.parents[k]]:
                mask[k] = True
        return mask

    def matches(self, other: Skeleton) -> bool:
        """Same joints (names and parents): poses of one fit the other."""
        return self is other or (self.names == other.names and np.array_equal(self.parents, other.parents))

    def check_pose(self, pose: Pose, *, field: str) -> None:
        if not isinstance(pose, Pose):
            raise ValidationError(f"{field} must be a flockkit.Pose; got {type(pose).__name__}")
        if pose.n_joints != self.n_joints:
            raise ValidationError(f"{field} has {pose.n_joints} joints; the skeleton has {self.n_joints}")

    def world(self, pose: Pose, *, dtype=np.float64) -> np.ndarray:
        """World (model-space) joint matrices (..., J, 4, 4) of `pose` (..., J): each joint's
        ``parent world @ T R S``, one vectorized step per depth of the tree."""
        self.check_pose(pose, field="pose")
        world = rigid.trs(pose.translations, pose.rotations, self.scales, dtype=dtype)
        for level in range(1, int(self.depth.max()) + 1):
            joints = np.flatnonzero(self.depth == level)
            world[..., joints, :, :] = world[..., self.parents[joints], :, :] @ world[..., joints, :, :]
        return world

    def positions(self, pose: Pose) -> np.ndarray:
        """World joint positions (..., J, 3) of `pose`: what a stick figure draws."""
        return self.world(pose)[..., :3, 3]


@attrs.frozen(kw_only=True)
class Event:
    """A tag on a clip's timeline (a footstep, a cheer's peak): `name` at `time` seconds."""

    time: float = attrs.field(converter=float)
    name: str = attrs.field()

    @name.validator
    def _check(self, attribute, value):
        if not isinstance(value, str) or not value:
            raise ValidationError(f"Event.name must be a non-empty string; got {value!r}")
        if not np.isfinite(self.time) or self.time < 0:
            raise ValidationError(f"Event.time must be a finite time >= 0 in seconds; got {self.time}")


def _fps(value, field: str = "SkeletalClip.fps") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValidationError(f"{field} must be a positive number; got {value!r}")
    if not np.isfinite(value) or value <= 0:
        raise ValidationError(f"{field} must be a positive number; got {value!r}")
    return float(value)


# How a channel's keys are joined (glTF 2.0, Appendix C): LINEAR (slerp for rotations), STEP (each
# key held until the next) and CUBICSPLINE (Hermite, with an in- and an out-tangent per key).
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
_WIDTH = {"rotation": 4, "translation": 3}
# The frame rate of a clip made of channels that have no two keys to take a rate from.
DEFAULT_FPS = 30.0


def sample_keys(key_times, values, times, interpolation: str = "LINEAR", *, rotation: bool = False,
                in_tangents=None, out_tangents=None) -> np.ndarray:  # fmt: skip
    """Keyed values at `times`, as glTF 2.0 defines them (Appendix C), for keys that share times.

    Parameters
    ----------
    key_times : (K,)
        Strictly increasing key times in seconds.
    values : (K, ..., W)
        Each key's values, any number of curves on the middle axes (joints, morph targets).
    times : (T,)
        Where to evaluate: before the first key and after the last the end keys hold, and at a
        key's own time its value is returned as it is.
    interpolation : "LINEAR", "STEP" or "CUBICSPLINE"
        LINEAR: ``(1 - t) v_k + t v_k+1`` with t the share of the way from key k to key k + 1, or
        for rotations (unit quaternions x, y, z, w, as LINEAR and STEP keys must be) spherical
        linear interpolation the shorter way round, ``sin((1 - t) a) / sin(a) v_k +
        s sin(t a) / sin(a) v_k+1`` with a the arccosine of ``|v_k . v_k+1|`` and s its sign.
        STEP: ``v_k`` until key k + 1. CUBICSPLINE: the Hermite spline ``(2t^3 - 3t^2 + 1) v_k +
        d (t^3 - 2t^2 + t) b_k + (-2t^3 + 3t^2) v_k+1 + d (t^3 - t^2) a_k+1``, d the keys'
        interval in seconds, `out_tangents` b and `in_tangents` a (K, ..., W) in units per
        second.
    rotation : bool
        The values are quaternions; a CUBICSPLINE result is normalized (a spline through zero,
        which the specification asks exporters never to write, gives the earlier key there).

    Returns
    -------
    (T, ..., W) float64
    """
    if interpolation not in INTERPOLATIONS:
        raise ValidationError(f"sample_keys: interpolation must be one of {', '.join(INTERPOLATIONS)}; got "
                              f"{interpolation!r}")  # fmt: skip
    if interpolation == "CUBICSPLINE" and (in_tangents is None or out_tangents is None):
        raise ValidationError("sample_keys: CUBICSPLINE needs in_tangents and out_tangents")
    keys = _Keys(np.asarray(key_times, dtype=np.float64), np.asarray(values, dtype=np.float64), interpolation,
                 rotation, in_tangents, out_tangents)  # fmt: skip
    return keys(np.asarray(times, dtype=np.float64))


class _Keys:
    """Keys that share times, with what every evaluation of them would recompute worked out once
    (a pose is sampled every frame for every stream): for slerp, each interval's angle and its
    far key turned to the near side."""

    def __init__(self, times, values, interpolation, rotation, in_tangents=None, out_tangents=None):
        self.times, self.values, self.interpolation, self.rotation = times, values, interpolation, rotation
        self.last = len(times) - 2
        self.tail = (1,) * (values.ndim - 1)
        if interpolation == "CUBICSPLINE":
            self.in_tangents = np.asarray(in_tangents, dtype=np.float64)
            self.out_tangents = np.asarray(out_tangents, dtype=np.float64)
        if len(times) > 1 and rotation and interpolation == "LINEAR":
            near, far = values[:-1], values[1:]
            dot = np.sum(near * far, axis=-1, keepdims=True)
            self.far = np.where(dot < 0, -far, far)
            # identical keys: an angle too small to matter, so that sin(t a) / sin(a) is t, not 0 / 0
            self.angle = np.maximum(np.arccos(np.minimum(np.abs(dot), 1.0)), 1e-12)
            self.sine = np.sin(self.angle)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        times, values = self.times, self.values
        if self.last < 0:
            return np.broadcast_to(values[0], t.shape + values.shape[1:]).copy()
        at = np.minimum(np.maximum(t, times[0]), times[-1])
        k = np.minimum(times.searchsorted(at, side="right") - 1, self.last)
        span = (times[k + 1] - times[k]).reshape(t.shape + self.tail)
        u = (at - times[k]).reshape(span.shape) / span
        if self.interpolation == "STEP":
            return np.where(u >= 1, values[k + 1], values[k])  # u reaches 1 only at the last key
        if self.interpolation == "LINEAR" and not self.rotation:
            return (1 - u) * values[k] + u * values[k + 1]
        if self.interpolation == "LINEAR":
            angle, sine = self.angle[k], self.sine[k]
            return np.sin((1 - u) * angle) / sine * values[k] + np.sin(u * angle) / sine * self.far[k]
        u2 = u * u
        u3 = u2 * u
        before = values[k]
        result = ((2 * u3 - 3 * u2 + 1) * before + span * (u3 - 2 * u2 + u) * self.out_tangents[k]
                  + (-2 * u3 + 3 * u2) * values[k + 1] + span * (u3 - u2) * self.in_tangents[k + 1])  # fmt: skip
        if not self.rotation:
            return result
        length = np.sqrt(np.sum(result * result, axis=-1, keepdims=True))
        if not (length > 1e-12).all():
            result = np.where(length > 1e-12, result, before)
            length = np.sqrt(np.sum(result * result, axis=-1, keepdims=True))
        return result / length


def _key_times(value, *, field: str) -> np.ndarray:
    times = readonly_float(value, field=field)
    if times.ndim != 1 or len(times) == 0:
        raise ValidationError(f"{field} must be a non-empty 1D array of seconds; got shape {times.shape}")
    if not np.all(np.isfinite(times)) or times[0] < 0 or np.any(np.diff(times) <= 0):
        raise ValidationError(f"{field} must be finite seconds >= 0 that increase strictly")
    return times


@attrs.frozen(kw_only=True, eq=False)
class Channel:
    """One joint's rotation or translation keyed at its own times and joined as glTF 2.0 defines
    (Appendix C; see :func:`sample_keys`): the parts a :class:`SkeletalClip` is made of when its
    keys are not evenly spaced frames of every joint (glTF animations, hand-keyed clips).

    Parameters
    ----------
    joint : str or int
        The joint's name or index in the clip's skeleton.
    path : {"rotation", "translation"}
        What the channel moves: the joint's local rotation or translation.
    times : (K,)
        Key times in seconds, >= 0, strictly increasing; the clip holds the first key before it.
    values : (K, 4) or (K, 3)
        Rotations: quaternions x, y, z, w, for LINEAR and STEP unit ones (lengths within 1e-3 of
        1 normalized, others refused), for CUBICSPLINE as given (the spline runs through the
        values as they are and normalizes its result); translations: vectors.
    interpolation : {"LINEAR", "STEP", "CUBICSPLINE"}
    in_tangents, out_tangents : (K, 4) or (K, 3), optional
        CUBICSPLINE only (and needed there): each key's incoming and outgoing derivative, in
        units per second.
    """

    joint: str | int = attrs.field()
    path: str = attrs.field()
    times: np.ndarray = attrs.field(converter=lambda v: _key_times(v, field="Channel.times"))
    values: np.ndarray = attrs.field()
    interpolation: str = attrs.field(default="LINEAR")
    in_tangents: np.ndarray | None = attrs.field(default=None)
    out_tangents: np.ndarray | None = attrs.field(default=None)

    def __attrs_post_init__(self):
        if isinstance(self.joint, bool) or not isinstance(self.joint, (str, int, np.integer)):
            raise ValidationError(f"Channel.joint must be a joint name or index; got {self.joint!r}")
        if self.path not in _WIDTH:
            raise ValidationError(f"Channel.path must be 'rotation' or 'translation'; got {self.path!r}")
        if self.interpolation not in INTERPOLATIONS:
            raise ValidationError(
                f"Channel.interpolation must be one of {', '.join(INTERPOLATIONS)}; got {self.interpolation!r}"
            )
        shape = (len(self.times), _WIDTH[self.path])
        cubic = self.interpolation == "CUBICSPLINE"
        if cubic and shape[0] < 2:
            raise ValidationError("Channel: a CUBICSPLINE channel needs at least 2 keys")
        if self.path == "rotation" and not cubic:
            values = unit_quaternions(self.values, field="Channel.values")
        else:
            values = _finite(self.values, field="Channel.values", shape_tail=(shape[1],))
            if self.path == "rotation" and not np.all(np.linalg.norm(values, axis=-1) > 1e-12):
                raise ValidationError("Channel.values holds a rotation of length zero")
        if values.shape != shape:
            raise ValidationError(f"Channel.values must have shape {shape} ({len(self.times)} keys of a {self.path}); "
                                  f"got {values.shape}")  # fmt: skip
        object.__setattr__(self, "values", values)
        for name in ("in_tangents", "out_tangents"):
            given = getattr(self, name)
            if not cubic:
                if given is not None:
                    raise ValidationError(
                        f"Channel.{name} are for CUBICSPLINE channels; this one is {self.interpolation}"
                    )
                continue
            if given is None:
                raise ValidationError(f"Channel.{name} are needed by a CUBICSPLINE channel")
            tangents = _finite(given, field=f"Channel.{name}", shape_tail=(shape[1],))
            if tangents.shape != shape:
                raise ValidationError(f"Channel.{name} must have shape {shape}; got {tangents.shape}")
            object.__setattr__(self, name, tangents)

    @property
    def duration(self) -> float:
        """The time of the last key."""
        return float(self.times[-1])

    def sample(self, times) -> np.ndarray:
        """Values (T, W) at `times` in seconds (rotations normalized)."""
        return sample_keys(self.times, self.values, times, self.interpolation, rotation=self.path == "rotation",
                           in_tangents=self.in_tangents, out_tangents=self.out_tangents)  # fmt: skip


class _Track:
    """Channels of several joints that share a path, key times and interpolation, sampled at once:
    values (K, n, W) for the joints `joints` (n,)."""

    def __init__(self, *, rotation, interpolation, times, joints, values, in_tangents=None, out_tangents=None):
        self.rotation, self.joints, self.times = rotation, joints, times
        self.keys = _Keys(times, values, interpolation, rotation, in_tangents, out_tangents)

    def sample(self, t: np.ndarray) -> np.ndarray:
        return self.keys(t)


def _frame_count(duration: float, fps: float) -> int:
    """Frames k / fps, k = 0 .. ceil(duration x fps), that reach `duration`: an end within a
    thousandth of a frame past a frame (float32 key times round) counts as that frame."""
    return math.ceil(duration * fps - 1e-3) + 1


def _optional(converter):
    return lambda value: None if value is None else converter(value)


@attrs.frozen(kw_only=True, eq=False)
class SkeletalClip:
    """A skeletal clip: each joint's local rotation and translation over time, given either as
    frames (every joint at `fps`) or as channels (each joint's keys at their own times).

    Sampling (:meth:`sample`) gives at any time what the clip's keys define: between a frames
    clip's frames, rotations slerped (the shorter way) and translations interpolated linearly
    (how flockkit plays BVH takes between their frames); a clip of channels as glTF 2.0 defines
    (LINEAR, STEP, CUBICSPLINE; :func:`sample_keys`). Keys are never resampled unless asked
    (:meth:`resampled`).

    Parameters
    ----------
    skeleton : Skeleton
    fps : float, optional
        Frames per second: the rate of the frames given, or, for a clip of channels, of the evenly
        spaced frames it is sampled at for the tools that work on frames (foot planting, motion
        graphs; default the channels' key rate, the inverse of the median interval between keys).
    rotations : (T, J, 4), optional
        Frames: local joint rotations, unit quaternions (x, y, z, w); lengths within 1e-3 of 1
        are normalized, others refused. For a clip of channels, computed: the clip sampled at
        ``k / fps``, k = 0 .. ceil(duration x fps) (the last holding the end).
    translations : (T, 3) or (T, J, 3), optional
        Frames: the root's translation (every other joint keeps its rest translation), or every
        joint's. Computed for a clip of channels, as `rotations`.
    channels : sequence of Channel, optional
        Instead of frames: at most one per joint and path; a joint a channel does not move keeps
        its rest rotation or translation.
    events : sequence of Event, optional
        Tags on the timeline, at times within the clip.
    name : str
    root_motion : RootMotion, optional
        The ground motion taken out of the clip (``extract_root_motion``): a clip played in place
        whose root advances by this track as it plays (``Driver(root_motion="clip")``). It spans
        the clip: its last time is the clip's duration.
    """

    skeleton: Skeleton = attrs.field()
    fps: float | None = attrs.field(default=None, converter=_optional(_fps))
    rotations: np.ndarray | None = attrs.field(
        default=None, converter=_optional(lambda v: unit_quaternions(v, field="SkeletalClip.rotations"))
    )
    translations: np.ndarray | None = attrs.field(default=None)
    channels: tuple = attrs.field(default=(), converter=tuple, repr=lambda c: f"<{len(c)} channels>")
    events: tuple = attrs.field(default=(), converter=tuple)
    name: str = attrs.field(default="clip")
    root_motion: RootMotion | None = attrs.field(default=None, repr=False)
    _tracks: tuple = attrs.field(init=False, repr=False)
    _plan: tuple = attrs.field(init=False, repr=False)
    _duration: float = attrs.field(init=False, repr=False)

    def __attrs_post_init__(self):
        if not isinstance(self.skeleton, Skeleton):
            raise ValidationError(
                f"SkeletalClip.skeleton must be a flockkit.Skeleton; got {type(self.skeleton).__name__}"
            )
        if self.channels:
            if self.rotations is not None or self.translations is not None:
                raise ValidationError(
                    "SkeletalClip takes frames (fps, rotations, translations) or channels, not both: a clip of "
                    "channels computes its frames from them"
                )
            self._from_channels()
        else:
            self._from_frames()
        for k, event in enumerate(self.events):
            if not isinstance(event, Event):
                raise ValidationError(f"SkeletalClip.events[{k}] must be a flockkit.Event; got {type(event).__name__}")
            if event.time > self.duration + 1e-9:
                raise ValidationError(
                    f"SkeletalClip.events[{k}] at {event.time} s is past the clip's end ({self.duration:.6g} s)"
                )
        object.__setattr__(self, "events", tuple(sorted(self.events, key=lambda e: e.time)))
        track = self.root_motion
        if track is not None:
            if not isinstance(track, RootMotion):
                raise ValidationError(
                    f"SkeletalClip.root_motion must be a flockkit.crowd.RootMotion; got {type(track).__name__}"
                )
            if track.up_axis != self.skeleton.up_axis:
                raise ValidationError(f"SkeletalClip.root_motion is on the ground of up axis {track.up_axis!r}; the "
                                      f"skeleton's up axis is {self.skeleton.up_axis!r}")  # fmt: skip
            if abs(track.duration - self.duration) > 1e-6 * max(1.0, self.duration):
                raise ValidationError(f"SkeletalClip.root_motion lasts {track.duration:.6g} s; the clip lasts "
                                      f"{self.duration:.6g} s (a track spans its clip)")  # fmt: skip

    def _from_frames(self) -> None:
        if self.rotations is None or self.translations is None or self.fps is None:
            missing = [n for n in ("fps", "rotations", "translations") if getattr(self, n) is None]
            raise ValidationError(
                f"SkeletalClip needs its frames (fps, rotations, translations) or channels; {', '.join(missing)} "
                "missing"
            )
        j = self.skeleton.n_joints
        if self.rotations.ndim != 3 or self.rotations.shape[1] != j or len(self.rotations) == 0:
            raise ValidationError(
                f"SkeletalClip.rotations must have shape (T, {j}, 4) with T >= 1; got {self.rotations.shape}"
            )
        frames = len(self.rotations)
        translations = _finite(self.translations, field="SkeletalClip.translations", shape_tail=(3,))
        if translations.shape == (frames, 3):
            full = np.broadcast_to(self.skeleton.rest.translations, (frames, j, 3)).copy()
            full[:, self._roots] = translations[:, None]
            translations = full
            translations.setflags(write=False)
        elif translations.shape != (frames, j, 3):
            raise ValidationError(
                f"SkeletalClip.translations must have shape ({frames}, 3) or ({frames}, {j}, 3); "
                f"got {translations.shape}"
            )
        object.__setattr__(self, "translations", translations)
        times = np.arange(frames) / self.fps
        every = np.arange(j)
        tracks = (
            _Track(rotation=True, interpolation="LINEAR", times=times, joints=every, values=self.rotations),
            _Track(rotation=False, interpolation="LINEAR", times=times, joints=every, values=translations),
        )
        self._set_tracks(tracks)
        object.__setattr__(self, "_duration", (frames - 1) / self.fps)

    def _from_channels(self) -> None:
        groups: dict = {}
        taken = set()
        for k, channel in enumerate(self.channels):
            if not isinstance(channel, Channel):
                raise ValidationError(
                    f"SkeletalClip.channels[{k}] must be a flockkit.Channel; got {type(channel).__name__}"
                )
            joint = self._joint(channel.joint, k)
            if (joint, channel.path) in taken:
                raise ValidationError(
                    f"SkeletalClip.channels[{k}] moves the {channel.path} of joint {self.skeleton.names[joint]!r}, "
                    "which an earlier channel moves"
                )
            taken.add((joint, channel.path))
            key = (channel.path, channel.interpolation, channel.times.tobytes())
            groups.setdefault(key, []).append((joint, channel))
        tracks = []
        for (path, interpolation, _), members in groups.items():
            chosen = [c for _, c in members]
            cubic = interpolation == "CUBICSPLINE"
            stacked = {"values": np.stack([c.values for c in chosen], axis=1)}
            if cubic:
                stacked["in_tangents"] = np.stack([c.in_tangents for c in chosen], axis=1)
                stacked["out_tangents"] = np.stack([c.out_tangents for c in chosen], axis=1)
            tracks.append(_Track(rotation=path == "rotation", interpolation=interpolation, times=chosen[0].times,
                                 joints=np.array([j for j, _ in members]), **stacked))  # fmt: skip
        duration = max(c.duration for c in self.channels)
        fps = self.fps
        if fps is None:
            steps = np.concatenate([np.diff(c.times) for c in self.channels])
            fps = float(np.round(1.0 / np.median(steps), 3)) if len(steps) else DEFAULT_FPS
        frames = _frame_count(duration, fps)
        validate.allocation(frames * self.skeleton.n_joints * 14,
                            f"SkeletalClip {self.name!r}: frames of {duration:g} s at {fps:g} fps")  # fmt: skip
        object.__setattr__(self, "fps", fps)
        self._set_tracks(tracks)
        object.__setattr__(self, "_duration", duration)
        pose = self._evaluate(np.arange(frames) / fps)
        pose.rotations.setflags(write=False)
        pose.translations.setflags(write=False)
        object.__setattr__(self, "rotations", pose.rotations)
        object.__setattr__(self, "translations", pose.translations)

    def _set_tracks(self, tracks) -> None:
        """The tracks, and per path (rotations, translations) the plan of sampling: the rest
        values where some joint has no track (else None) and the tracks."""
        plan = []
        for steady, rotation in ((self.skeleton.rest.rotations, True), (self.skeleton.rest.translations, False)):
            chosen = tuple(track for track in tracks if track.rotation == rotation)
            covered = sum(len(track.joints) for track in chosen) == self.skeleton.n_joints
            plan.append((None if covered else steady, chosen))
        object.__setattr__(self, "_tracks", tuple(tracks))
        object.__setattr__(self, "_plan", tuple(plan))

    def _joint(self, joint, k: int) -> int:
        if isinstance(joint, str):
            try:
                return self.skeleton.index(joint)
            except ValidationError as exc:
                raise ValidationError(f"SkeletalClip.channels[{k}]: {exc}") from None
        if not 0 <= joint < self.skeleton.n_joints:
            raise ValidationError(
                f"SkeletalClip.channels[{k}].joint is {joint}; the skeleton's joints are 0 .. "
                f"{self.skeleton.n_joints - 1}"
            )
        return int(joint)

    @property
    def _roots(self) -> np.ndarray:
        return np.flatnonzero(self.skeleton.parents < 0)

    @property
    def n_frames(self) -> int:
        """The number of frames (`rotations`, `translations`)."""
        return len(self.rotations)

    @property
    def duration(self) -> float:
        """Seconds from 0 to the last key (a frames clip: its last frame); a looping clip repeats
        with this period."""
        return self._duration

    @property
    def key_times(self) -> np.ndarray:
        """Every time a key of the clip lies at, sorted (a frames clip: its frames' times)."""
        return np.unique(np.concatenate([track.times for track in self._tracks]))

    def _evaluate(self, t: np.ndarray) -> Pose:
        found = []
        for (steady, tracks), width in zip(self._plan, (4, 3)):
            if steady is None and len(tracks) == 1:  # one track moves every joint: its result is the array
                found.append(tracks[0].sample(t))
                continue
            out = np.empty((len(t), self.skeleton.n_joints, width))
            if steady is not None:
                out[:] = steady
            for track in tracks:
                out[:, track.joints] = track.sample(t)
            found.append(out)
        return Pose._adopt(*found)

    def sample(self, times) -> Pose:
        """Poses (len(times), J) at `times` in seconds, as the clip's keys define them (see the
        class): exact at every key, the first and last keys held before and after them."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise ValidationError("SkeletalClip.sample needs finite times (a number or a 1D array)")
        return self._evaluate(t)

    def resampled(self, fps) -> SkeletalClip:
        """This clip as frames at `fps`: its poses at ``k / fps``, k = 0 .. ceil(duration x fps)
        (the last holding its end), slerped between from then on. Lossy wherever keys fall
        between the new frames or are not LINEAR: for an export or a buffer that must hold
        evenly spaced frames, not for playing the clip."""
        fps = _fps(fps, "SkeletalClip.resampled: fps")
        frames = _frame_count(self.duration, fps)
        validate.allocation(frames * self.skeleton.n_joints * 14,
                            f"clip {self.name!r} ({self.duration:g} s) resampled at {fps:g} fps")  # fmt: skip
        pose = self._evaluate(np.arange(frames) / fps)
        track = None if self.root_motion is None else self.root_motion.resampled(frames, fps)
        return SkeletalClip(skeleton=self.skeleton, fps=fps, rotations=pose.rotations, translations=pose.translations,
                            events=self.events, name=self.name, root_motion=track)  # fmt: skip

    def pose(self, frame: int) -> Pose:
        """The pose of frame `frame` (J, ...)."""
        return Pose._adopt(self.rotations[frame], self.translations[frame])


# -- root motion ------------------------------------------------------------------------------
#
# Root motion lives on the ground of the character's own model space: the plane across its up
# axis, in its own units. A ground transform is (..., 4): a translation (x, y, z; its component
# along the up axis is 0) and a heading (radians about the up axis, right-handed, unwrapped so
# that turns accumulate). The two ground axes are the ones after the up axis in cyclic order
# (y up: z then x), and a heading turns the first towards the second, so that a point of the
# ground is a complex number first + i second and a heading is multiplication by exp(i heading).

# A clip carries root motion when its motion joint ends its loop this share of the character's
# height (its rest pose's spread along its up axis) away from where it began...
ROOT_MOTION_TOLERANCE = 0.01
# ...or turned by more than this (radians; one degree).
ROOT_TURN_TOLERANCE = math.radians(1.0)
_AXIS = {"x": 0, "y": 1, "z": 2}


def _ground_axes(up: str) -> tuple[int, int]:
    u = _AXIS[up]
    return (u + 1) % 3, (u + 2) % 3


def ground_complex(transforms, up: str) -> tuple[np.ndarray, np.ndarray]:
    """Ground transforms (..., 4) as (complex positions, headings)."""
    a, b = _ground_axes(up)
    transforms = np.asarray(transforms, dtype=np.float64)
    return transforms[..., a] + 1j * transforms[..., b], transforms[..., 3]


def ground_array(position, heading, up: str) -> np.ndarray:
    """(complex positions, headings) as ground transforms (..., 4)."""
    a, b = _ground_axes(up)
    position = np.asarray(position)
    out = np.zeros(position.shape + (4,))
    out[..., a], out[..., b], out[..., 3] = position.real, position.imag, heading
    return out


def compose_ground(first, second, up: str) -> np.ndarray:
    """Ground transforms `first` then `second` in `first`'s frame (..., 4): ``first @ second`` as
    matrices (``ground_matrices``)."""
    p, h = ground_complex(first, up)
    q, g = ground_complex(second, up)
    return ground_array(p + np.exp(1j * h) * q, h + g, up)


def relative_ground(first, second, up: str) -> np.ndarray:
    """The ground transform taking `first` to `second` (..., 4): ``inv(first) @ second``."""
    p, h = ground_complex(first, up)
    q, g = ground_complex(second, up)
    return ground_array(np.exp(-1j * h) * (q - p), g - h, up)


def ground_matrices(transforms, up: str) -> np.ndarray:
    """Ground transforms (..., 4) as 4 x 4 matrices (..., 4, 4) in the character's model space."""
    a, b = _ground_axes(up)
    transforms = np.asarray(transforms, dtype=np.float64)
    c, s = np.cos(transforms[..., 3]), np.sin(transforms[..., 3])
    m = np.zeros(transforms.shape[:-1] + (4, 4))
    m[..., :3, :3] = np.eye(3)
    m[..., a, a], m[..., a, b], m[..., b, a], m[..., b, b] = c, -s, s, c
    m[..., :3, 3] = transforms[..., :3]
    m[..., 3, 3] = 1.0
    return m


def _heading_of(rotations: np.ndarray, up: str) -> np.ndarray:
    """The twist (radians) about the `up` axis of rotation matrices (..., 3, 3): of a unit
    quaternion (v, w), 2 atan2(v . up, w)."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_quat()
    return (2 * np.arctan2(q[:, _AXIS[up]], q[:, 3])).reshape(rotations.shape[:-2])


@attrs.frozen(kw_only=True, eq=False)
class RootMotion:
    """The ground motion of a clip's motion joint (its hips, its root): per key time, where the
    joint stands on the ground and how far it has turned about the up axis, in the character's
    model space and units.

    Parameters
    ----------
    times : (F,)
        Key times in seconds from 0, strictly increasing; the last is the clip's duration.
    translations : (F, 3)
        The joint's ground position (its component along `up_axis` is 0), keyed at `times` and
        linear between them.
    headings : (F,)
        Its turn about `up_axis` since time 0 (radians, unwrapped, right-handed: y up turns z
        towards x), linear between keys.
    up_axis : str
        The character's up axis (its skeleton's).
    joint : str
        The joint it was taken from.

    Attributes
    ----------
    loop : (4,)
        The ground transform from the clip's start to its end (``relative_ground`` of the first
        and last keys): what one loop of the clip adds to an agent's root.
    """

    times: np.ndarray = attrs.field(converter=lambda v: _key_times(v, field="RootMotion.times"))
    translations: np.ndarray = attrs.field(
        converter=lambda v: _finite(v, field="RootMotion.translations", shape_tail=(3,))
    )
    headings: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="RootMotion.headings"))
    up_axis: str = attrs.field(converter=lambda v: check_up_axis(v, "RootMotion.up_axis"))
    joint: str = attrs.field(default="")
    loop: np.ndarray = attrs.field(init=False, repr=False)

    def __attrs_post_init__(self):
        f = len(self.times)
        if self.times[0] != 0:
            raise ValidationError(f"RootMotion.times must start at 0; got {self.times[0]}")
        if self.translations.shape != (f, 3) or self.headings.shape != (f,):
            raise ValidationError(f"RootMotion.translations must be ({f}, 3) and headings ({f},), one per time; got "
                                  f"{self.translations.shape} and {self.headings.shape}")  # fmt: skip
        if not np.all(np.isfinite(self.headings)):
            raise ValidationError("RootMotion.headings must be finite")
        if np.abs(self.translations[:, _AXIS[self.up_axis]]).max() > 0:
            raise ValidationError(f"RootMotion.translations must lie on the ground: 0 along the up axis "
                                  f"{self.up_axis!r}")  # fmt: skip
        keys = self.keys
        loop = relative_ground(keys[0], keys[-1], self.up_axis)
        loop.setflags(write=False)
        object.__setattr__(self, "loop", loop)

    @property
    def keys(self) -> np.ndarray:
        """The keys as ground transforms (F, 4)."""
        return np.concatenate([self.translations, self.headings[:, None]], axis=1)

    @property
    def duration(self) -> float:
        """Seconds from the first key to the last: the clip's duration."""
        return float(self.times[-1])

    def sample(self, times) -> np.ndarray:
        """Ground transforms (T, 4) at `times` in seconds: linear between keys, the end keys held
        outside them."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        keys = self.keys
        return np.stack([np.interp(t, self.times, keys[:, k]) for k in range(4)], axis=-1)

    def played(self, times, *, start: float = 0.0, rate: float = 1.0, loop: bool = True) -> np.ndarray:
        """Where the root has gone (T, 4) after playing the clip for `times` seconds from `start`
        seconds into it at `rate`: ground transforms relative to the root at time 0, each loop
        adding ``loop`` (so a turning clip walks a circle), or held at the end without `loop`."""
        u = start + rate * np.atleast_1d(np.asarray(times, dtype=np.float64))
        return relative_ground(self._unwrapped(np.array([start]), loop), self._unwrapped(u, loop), self.up_axis)

    def _unwrapped(self, u: np.ndarray, loop: bool) -> np.ndarray:
        """The root at clip time `u` (any number of loops on), relative to the first key."""
        period, first = self.duration, self.keys[0]
        if not loop or period <= 0:
            return relative_ground(first, self.sample(np.clip(u, 0, period)), self.up_axis)
        k = np.floor(u / period)
        within = relative_ground(first, self.sample(u - k * period), self.up_axis)
        step, turn = ground_complex(self.loop, self.up_axis)
        # k loops: turned k turn, moved step (1 + e^(i turn) + ... + e^(i (k - 1) turn))
        half = np.sin(turn / 2)
        series = np.where(abs(half) < 1e-12, k, np.exp(1j * (k - 1) * turn / 2) * np.sin(k * turn / 2)
                          / np.where(abs(half) < 1e-12, 1.0, half))  # fmt: skip
        loops = ground_array(step * series, k * turn, self.up_axis)
        return compose_ground(loops, within, self.up_axis)

    def resampled(self, frames: int, fps: float) -> RootMotion:
        """The track at ``k / fps``, k < `frames` (the end held), as ``SkeletalClip.resampled``
        keys the clip."""
        times = np.arange(frames) / fps
        keys = self.sample(times)
        return RootMotion(times=times, translations=keys[:, :3], headings=keys[:, 3], up_axis=self.up_axis,
                          joint=self.joint)  # fmt: skip


def _moving(clip: SkeletalClip) -> np.ndarray:
    """A mask (J,) of the joints whose rotation or translation the clip changes."""
    return (np.ptp(clip.rotations, axis=0).max(axis=1) > 1e-9) | (np.ptp(clip.translations, axis=0).max(axis=1) > 1e-9)


def _motion_joint(clip: SkeletalClip, joint) -> int:
    """The joint whose ground motion is the clip's root motion: `joint` by name, or the shallowest
    joint the clip moves (rotation or translation), of those the one with most joints below it
    (a body's hips, not a foot's target beside them); the first root if nothing moves."""
    skeleton = clip.skeleton
    if joint is not None:
        return skeleton.index(joint)
    moving = _moving(clip)
    if not moving.any():
        return int(np.flatnonzero(skeleton.parents < 0)[0])
    shallowest = np.flatnonzero(moving & (skeleton.depth == skeleton.depth[moving].min()))
    below = [int(skeleton.descendants(skeleton.names[j]).sum()) for j in shallowest]
    return int(shallowest[int(np.argmax(below))])


def _root_track(clip: SkeletalClip, joint: int) -> tuple[RootMotion, np.ndarray, np.ndarray]:
    """(the track, the key times, the joint's model-space matrices there)."""
    skeleton, up = clip.skeleton, clip.skeleton.up_axis
    times = np.minimum(np.arange(clip.n_frames) / clip.fps, clip.duration)
    if len(times) > 1 and times[-1] <= times[-2]:
        times = times[:-1]
    if times[-1] < clip.duration:
        times = np.append(times, clip.duration)
    world = skeleton.world(clip.sample(times))
    matrix = world[:, joint]
    a, b = _ground_axes(up)
    translations = np.zeros((len(times), 3))
    translations[:, a], translations[:, b] = matrix[:, a, 3], matrix[:, b, 3]
    linear = matrix[:, :3, :3] / np.linalg.norm(matrix[:, :3, :3], axis=1, keepdims=True)  # the joint's own scale out
    rotation = linear @ linear[0].T  # the turn since time 0, in model space
    headings = np.unwrap(_heading_of(rotation, up))
    track = RootMotion(times=times, translations=translations, headings=headings, up_axis=up,
                       joint=skeleton.names[joint])  # fmt: skip
    return track, times, world


def carries_root_motion(clip: SkeletalClip, *, joint=None, tolerance: float = ROOT_MOTION_TOLERANCE,
                        turn_tolerance: float = ROOT_TURN_TOLERANCE) -> bool:  # fmt: skip
    """Whether `clip` moves its character across the ground: its motion joint (`joint`, or as
    ``extract_root_motion`` chooses it) ends the clip more than `tolerance` times the
    character's height (its rest pose's spread along its up axis) from where it began, or
    turned by more than `turn_tolerance` radians. A loop played in place (a treadmill walk) does
    not, whatever its hips sway within the loop."""
    if not isinstance(clip, SkeletalClip):
        raise ValidationError(f"carries_root_motion needs a flockkit.SkeletalClip; got {type(clip).__name__}")
    track, _, _ = _root_track(clip, _motion_joint(clip, joint))
    heights = clip.skeleton.positions(clip.skeleton.rest)[:, _AXIS[clip.skeleton.up_axis]]
    height = float(np.ptp(heights)) or 1.0
    distance = float(np.linalg.norm(track.loop[:3]))
    return distance > tolerance * height or abs(float(track.loop[3])) > turn_tolerance


def extract_root_motion(clip: SkeletalClip, *, joint=None) -> SkeletalClip:
    """`clip` played in place, with the ground motion taken out as its ``root_motion``.

    The motion joint (`joint` by name; by default the shallowest joint the clip moves, of those
    the one with most joints below it: the Fox's and a BVH take's hips, the robot's body) has,
    at each key, a ground position (its model-space position with the component along the
    skeleton's up axis dropped) and a heading (its turn about the up axis since the first key).
    The in-place clip keeps the joint over the origin, facing as at the first key: the joint's
    model-space transform is ``inv(G(t)) @ W(t)``, G the ground transform of the track
    (``ground_matrices``), so that ``G(t) @`` the in-place pose gives the clip's pose back
    (exactly at the keys). Only the motion joint changes: it is keyed (LINEAR) at the clip's
    frames and its end; every other joint keeps its keys. Its parents must scale uniformly (as
    a similarity does), or the turn could not be taken out rigidly.
    """
    if not isinstance(clip, SkeletalClip):
        raise ValidationError(f"extract_root_motion needs a flockkit.SkeletalClip; got {type(clip).__name__}")
    skeleton, j = clip.skeleton, _motion_joint(clip, joint)
    track, times, world = _root_track(clip, j)
    parent = skeleton.parents[j]
    pose = clip.sample(times)
    # the joint and the siblings the clip moves with it (a robot's foot targets beside its body)
    moving = _moving(clip)
    rewritten = np.flatnonzero((skeleton.parents == parent) & (moving | (np.arange(skeleton.n_joints) == j)))
    above = world[:, parent] if parent >= 0 else np.broadcast_to(np.eye(4), world[:, j].shape)
    # X = inv(P) inv(G) P: inv(G) applied in model space, seen from the parent
    change = np.linalg.solve(above, np.linalg.solve(ground_matrices(track.keys, skeleton.up_axis), above))
    linear = change[:, :3, :3]
    if np.abs(linear @ np.swapaxes(linear, 1, 2) - np.eye(3)).max() > 1e-6:
        raise ValidationError(f"extract_root_motion: the joints above {skeleton.names[j]!r} scale unevenly; a turn "
                              "cannot be taken out of them rigidly")  # fmt: skip
    from scipy.spatial.transform import Rotation

    keyed = {}
    for k in rewritten.tolist():
        local = change @ rigid.trs(pose.translations[:, k], pose.rotations[:, k], np.ones(3))
        q = Rotation.from_matrix(local[:, :3, :3]).as_quat()
        flips = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0))  # one hemisphere, key to key
        q[1:] *= flips[:, None]
        keyed[k] = (q, local[:, :3, 3])
    if not clip.channels:
        rotations, translations = clip.rotations.copy(), clip.translations.copy()
        for k, (q, t) in keyed.items():
            rotations[:, k], translations[:, k] = q[: clip.n_frames], t[: clip.n_frames]
        return SkeletalClip(skeleton=skeleton, fps=clip.fps, rotations=rotations, translations=translations,
                            events=clip.events, name=clip.name, root_motion=track)  # fmt: skip
    kept = [c for c in clip.channels if (skeleton.index(c.joint) if isinstance(c.joint, str) else c.joint) not in keyed]
    for k, (q, t) in keyed.items():
        kept += [Channel(joint=k, path="rotation", times=times, values=q),
                 Channel(joint=k, path="translation", times=times, values=t)]  # fmt: skip
    return SkeletalClip(skeleton=skeleton, fps=clip.fps, channels=kept, events=clip.events, name=clip.name,
                        root_motion=track)  # fmt: skip
