"""Skeletons, poses and clips (paper 003, sections 3.1 and 3.4): the value types of skeletal
animation (what ``flockkit.io.read_clips`` reads from glTF skins and BVH, and the crowd runtime
plays), and forward kinematics vectorized over frames and over many poses at once.

A pose gives every joint a local transform relative to its parent: a rotation (a unit quaternion
x, y, z, w) and a translation; scales are the skeleton's, fixed at rest (clips do not animate
them). World (model-space) transforms are 4 x 4 matrices ``parent world @ T R S``, as a glTF viewer
composes its nodes.
"""

from __future__ import annotations

import attrs
import numpy as np

from . import rigid
from ._arrays import readonly_float, readonly_int
from .errors import ValidationError

__all__ = ["Pose", "Skeleton", "SkeletalClip", "Event", "stream_times"]

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

    Attributes
    ----------
    depth : (J,) int
        Each joint's number of ancestors (0 for a root), computed on construction.
    """

    names: tuple = attrs.field(converter=tuple)
    parents: np.ndarray = attrs.field(converter=_parents)
    rest: Pose | None = attrs.field(default=None)
    scales: np.ndarray | None = attrs.field(default=None)
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


def _fps(value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValidationError(f"SkeletalClip.fps must be a positive number; got {value!r}")
    if not np.isfinite(value) or value <= 0:
        raise ValidationError(f"SkeletalClip.fps must be a positive number; got {value!r}")
    return float(value)


@attrs.frozen(kw_only=True, eq=False)
class SkeletalClip:
    """A skeletal clip: poses sampled at `fps`.

    Parameters
    ----------
    skeleton : Skeleton
    fps : float
        Frames per second.
    rotations : (T, J, 4)
        Local joint rotations, unit quaternions (x, y, z, w); lengths within 1e-3 of 1 are
        normalized, others refused.
    translations : (T, 3) or (T, J, 3)
        The root's translation (every other joint keeps its rest translation), or every joint's.
    events : sequence of Event, optional
        Tags on the timeline, at times within the clip.
    name : str
    """

    skeleton: Skeleton = attrs.field()
    fps: float = attrs.field(converter=_fps)
    rotations: np.ndarray = attrs.field(converter=lambda v: unit_quaternions(v, field="SkeletalClip.rotations"))
    translations: np.ndarray = attrs.field()
    events: tuple = attrs.field(default=(), converter=tuple)
    name: str = attrs.field(default="clip")

    def __attrs_post_init__(self):
        if not isinstance(self.skeleton, Skeleton):
            raise ValidationError(
                f"SkeletalClip.skeleton must be a flockkit.Skeleton; got {type(self.skeleton).__name__}"
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
        for k, event in enumerate(self.events):
            if not isinstance(event, Event):
                raise ValidationError(f"SkeletalClip.events[{k}] must be a flockkit.Event; got {type(event).__name__}")
            if event.time > self.duration + 1e-9:
                raise ValidationError(
                    f"SkeletalClip.events[{k}] at {event.time} s is past the clip's end ({self.duration:.6g} s)"
                )
        object.__setattr__(self, "events", tuple(sorted(self.events, key=lambda e: e.time)))

    @property
    def _roots(self) -> np.ndarray:
        return np.flatnonzero(self.skeleton.parents < 0)

    @property
    def n_frames(self) -> int:
        return len(self.rotations)

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last; a looping clip repeats with this period."""
        return (self.n_frames - 1) / self.fps

    def sample(self, times) -> Pose:
        """Poses (len(times), J) at `times` in seconds, held before 0 and after the end: rotations
        interpolated on the sphere (nlerp: between frames a few degrees apart it strays from
        slerp by thousandths of a degree, at a fraction of the cost), translations linearly."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise ValidationError("SkeletalClip.sample needs finite times (a number or a 1D array)")
        frame = np.clip(t * self.fps, 0, self.n_frames - 1)
        k = np.minimum(frame.astype(np.int64), max(self.n_frames - 2, 0))
        u = (frame - k)[:, None, None]
        if self.n_frames == 1:
            return Pose._adopt(np.repeat(self.rotations, len(t), axis=0), np.repeat(self.translations, len(t), axis=0))
        rotations = rigid.nlerp(self.rotations[k], self.rotations[k + 1], u)
        translations = self.translations[k] + u * (self.translations[k + 1] - self.translations[k])
        return Pose._adopt(rotations, translations)

    def pose(self, frame: int) -> Pose:
        """The stored pose of frame `frame` (J, ...)."""
        return Pose._adopt(self.rotations[frame], self.translations[frame])
