"""Feature arrows (paper 002, section 4.2): per frame, an arrow whose length (normalized to [0, 1])
and direction describe the force an object is under (wind for a flag or a plant) or its own
movement (speed and heading for an animal, a flock, a character).

Stored as Cartesian vectors (T, D) of length at most 1; ``Features.spherical()`` gives the paper's
c = (tau, phi, theta): length, azimuth in the x-y plane from +x, and polar angle from the up axis
(+z; in 2D, pi / 2). Keyframed arrows are interpolated with :func:`interpolate_arrows`: their
direction along the great circle between keyframes, their length linearly.

An object that walks (an animal, a character) carries self-movement arrows: ``Features.speed``
says how fast an arrow of length 1 carries it, so each frame's arrow is its travel in its own
coordinates. :func:`stride_speed` measures that travel for a clip played in place, from the
points that carry it (its feet).
"""

from __future__ import annotations

import attrs
import numpy as np

from .._arrays import check_finite, readonly_float
from ..errors import ValidationError
from ..motion import Motion
from ..validate import number

__all__ = ["Features", "interpolate_arrows", "arrow_keyframes", "stride_speed"]

# Points within this share of an in-place clip's height of its lowest point in a frame carry it
# (they touch the ground): stride_speed measures how fast they move back (our choice; the Fox's
# paws and a generated walker's feet, tests/core/test_moving_scene.py).
CONTACT = 0.03


def _vectors(value) -> np.ndarray:
    array = readonly_float(value, field="Features.vectors")
    if array.ndim != 2 or array.shape[1] not in (2, 3) or len(array) == 0:
        raise ValidationError(f"Features.vectors must have shape (T, 2 or 3) with T >= 1; got {array.shape}")
    check_finite(array, field="Features.vectors")
    longest = float(np.linalg.norm(array, axis=1).max())
    if longest > 1 + 1e-9:
        raise ValidationError(
            f"Features.vectors must have lengths in [0, 1] (normalized); the longest is {longest:.6g}"
        )
    return array


def arrow_keyframes(keyframes, field: str, *, dims=None, duration=None) -> tuple[np.ndarray, np.ndarray]:
    """(times (K,), vectors (K, D)) of `keyframes`, a sequence of (time, vector) pairs, checked:
    at least one, times increasing (and within [0, duration]), vectors of one dimension and of
    length at most 1."""
    try:
        pairs = [(float(t), np.asarray(v, dtype=float)) for t, v in keyframes]
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{field} must be a sequence of (time, vector) pairs; got {keyframes!r}: {exc}") from None
    if not pairs:
        raise ValidationError(f"{field} needs at least one keyframe")
    times = np.array([t for t, _ in pairs])
    if len({v.shape for _, v in pairs}) != 1 or pairs[0][1].shape not in ((2,), (3,)):
        raise ValidationError(f"{field}: every vector must have 2 or 3 coordinates, all alike")
    vectors = np.stack([v for _, v in pairs])
    if dims is not None and vectors.shape[1] != dims:
        raise ValidationError(f"{field}: vectors have {vectors.shape[1]} coordinates; expected {dims}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(vectors))):
        raise ValidationError(f"{field}: times and vectors must be finite")
    if np.any(np.diff(times) <= 0):
        bad = int(np.argmax(np.diff(times) <= 0)) + 1
        raise ValidationError(f"{field}: keyframe times must increase; keyframe {bad} at t={times[bad]:g} does not")
    if duration is not None and (times[0] < -1e-9 or times[-1] > duration + 1e-9):
        raise ValidationError(f"{field}: keyframe times must lie in 0..{duration:g} s; got {times[0]:g}..{times[-1]:g}")
    lengths = np.linalg.norm(vectors, axis=1)
    if lengths.max() > 1 + 1e-9:
        raise ValidationError(f"{field}: arrow lengths are normalized to [0, 1]; got {lengths.max():.6g}")
    return times, vectors


def _slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Unit vectors along the great circle from unit `a` to unit `b` (rows), at fractions `u`;
    opposite directions turn through an axis perpendicular to `a`."""
    dot = np.clip(np.sum(a * b, axis=-1, keepdims=True), -1.0, 1.0)
    angle = np.arccos(dot)
    sine = np.sin(angle)
    near = sine < 1e-9
    opposite = near & (dot < 0)
    if np.any(opposite):  # half a turn: through the perpendicular to `a` (in 3D, nearest the up axis)
        perpendicular = np.zeros_like(a)
        if a.shape[-1] == 2:
            perpendicular = np.stack([-a[..., 1], a[..., 0]], axis=-1)
        else:
            up = np.array([0.0, 0.0, 1.0])
            perpendicular = up - np.sum(a * up, axis=-1, keepdims=True) * a
            flat = np.linalg.norm(perpendicular, axis=-1, keepdims=True) < 1e-9
            perpendicular = np.where(flat, np.array([1.0, 0.0, 0.0]), perpendicular)
            perpendicular /= np.linalg.norm(perpendicular, axis=-1, keepdims=True)
        turned = np.cos(np.pi * u) * a + np.sin(np.pi * u) * perpendicular
    else:
        turned = a
    safe = np.where(near, 1.0, sine)
    along = (np.sin((1 - u) * angle) * a + np.sin(u * angle) * b) / safe
    linear = (1 - u) * a + u * b
    return np.where(opposite, turned, np.where(near, linear, along))


def interpolate_arrows(times: np.ndarray, vectors: np.ndarray, at) -> np.ndarray:
    """Arrows (len(at), D) at times `at` from keyframes (`times` (K,), `vectors` (K, D)): length
    linear, direction along the great circle, held before the first keyframe and after the last.
    A zero-length keyframe takes the direction of its nearest non-zero neighbour (a gust that dies
    down keeps its heading)."""
    at = np.asarray(at, dtype=float)
    lengths = np.linalg.norm(vectors, axis=1)
    moving = np.flatnonzero(lengths > 1e-12)
    if len(moving) == 0:
        return np.zeros((len(at), vectors.shape[1]))
    nearest = moving[np.abs(np.arange(len(vectors))[:, None] - moving[None, :]).argmin(axis=1)]
    directions = vectors[nearest] / lengths[nearest, None]
    if len(times) == 1:
        return np.repeat(vectors[:1], len(at), axis=0)
    clipped = np.clip(at, times[0], times[-1])
    k = np.clip(np.searchsorted(times, clipped, side="right") - 1, 0, len(times) - 2)
    u = ((clipped - times[k]) / (times[k + 1] - times[k]))[:, None]
    length = (1 - u) * lengths[k, None] + u * lengths[k + 1, None]
    return length * _slerp(directions[k], directions[k + 1], u)


def _speed(value):
    return None if value is None else number(value, "Features.speed", minimum=0, strict=True)


@attrs.frozen(kw_only=True, eq=False)
class Features:
    """Feature arrows of a source motion, one per frame: `vectors` (T, D), length in [0, 1]; `dt`
    seconds between frames.

    `speed` None: the arrows are forces the object is under (wind on a flag); an object placed in
    a scene stays where it stands. A number: the arrows are self-movement (section 4.2's "moving
    speed and facing direction"): played in place, frame t carries the object along its arrow at
    length x `speed` units per second (its clip's ground speed), so a scene moves and turns it
    after its targets (``flockkit.scene.movement``)."""

    vectors: np.ndarray = attrs.field(converter=_vectors)
    dt: float = attrs.field(converter=lambda v: number(v, "Features.dt", minimum=0, strict=True))
    speed: float | None = attrs.field(default=None, converter=_speed)

    @property
    def moves(self) -> bool:
        """Whether these are self-movement arrows (`speed` is set)."""
        return self.speed is not None

    @property
    def n_frames(self) -> int:
        return len(self.vectors)

    @property
    def lengths(self) -> np.ndarray:
        """The paper's tau: arrow lengths in [0, 1], (T,)."""
        return np.linalg.norm(self.vectors, axis=1)

    def spherical(self) -> np.ndarray:
        """(T, 3): the paper's (tau, phi, theta): length, azimuth in the x-y plane from +x, and
        polar angle from +z (pi / 2 in 2D)."""
        v = self.vectors
        z = v[:, 2] if v.shape[1] == 3 else np.zeros(len(v))
        tau = self.lengths
        theta = np.where(tau > 0, np.arccos(np.clip(z / np.where(tau > 0, tau, 1), -1, 1)), np.pi / 2)
        return np.column_stack([tau, np.arctan2(v[:, 1], v[:, 0]), theta])

    def __eq__(self, other):
        if not isinstance(other, Features):
            return NotImplemented
        return self.dt == other.dt and self.speed == other.speed and np.array_equal(self.vectors, other.vectors)

    __hash__ = None

    @classmethod
    def from_keyframes(cls, keyframes, *, n_frames: int, dt: float, speed: float | None = None) -> Features:
        """Features of `n_frames` frames from a few keyframed arrows, ``[(time, vector), ...]``
        (times in seconds, increasing, within the motion; vectors of length at most 1):
        direction along the great circle, length linearly, held outside the keyframes. `speed`
        as for Features (None: forces)."""
        dt = number(dt, "Features.from_keyframes: dt", minimum=0, strict=True)
        times, vectors = arrow_keyframes(keyframes, "Features.from_keyframes: keyframes", duration=(n_frames - 1) * dt)
        return cls(vectors=interpolate_arrows(times, vectors, np.arange(n_frames) * dt), dt=dt, speed=speed)

    @classmethod
    def from_stride(cls, motion: Motion, *, forward, contact: float = CONTACT) -> Features:
        """Self-movement arrows of a clip played in place (a walk, a run) facing `forward` (a
        vector in its ground plane, x and y): every arrow `forward` at length 1, and `speed` the
        clip's :func:`stride_speed` along it, so that a scene moves the object as fast as its feet
        push back and they do not slide."""
        if not isinstance(motion, Motion) or motion.dims != 3:
            raise ValidationError("Features.from_stride needs a 3D flockkit.Motion (z up), such as a mesh's")
        direction = _ground_direction(forward, "Features.from_stride: forward")
        speed = stride_speed(motion, forward=direction, contact=contact)
        if speed <= 0:
            raise ValidationError(
                f"Features.from_stride: the points that carry the clip do not move back along forward "
                f"{direction[:2].tolist()} (their median speed along it is {-speed:.3g} units/s forwards): it does "
                f"not walk that way in place; give the direction it faces"
            )
        return cls(vectors=np.tile(direction, (motion.n_frames, 1)), dt=motion.dt, speed=speed)

    @classmethod
    def from_motion(cls, motion: Motion, *, top_speed: float | None = None) -> Features:
        """Features of a moving object (an animal, a flock, a character) from its own motion: the
        heading of its center of mass, and its speed over `top_speed` (default: its fastest) as
        the length. No hand annotation is needed. A motion that never moves has zero arrows."""
        if not isinstance(motion, Motion):
            raise ValidationError(f"Features.from_motion needs a flockkit.Motion; got {type(motion).__name__}")
        velocity = np.gradient(motion.center_of_mass(), motion.dt, axis=0) if motion.n_frames > 1 else None
        if velocity is None:
            return cls(vectors=np.zeros((1, motion.dims)), dt=motion.dt)
        speed = np.linalg.norm(velocity, axis=1)
        top = float(speed.max()) if top_speed is None else number(top_speed, "top_speed", minimum=0, strict=True)
        scale = 1.0 / top if top > 0 else 0.0
        vectors = velocity * scale
        lengths = np.linalg.norm(vectors, axis=1, keepdims=True)
        vectors = np.where(lengths > 1, vectors / np.maximum(lengths, 1e-300), vectors)  # faster than top_speed: 1
        return cls(vectors=vectors, dt=motion.dt)


def _ground_direction(forward, field: str) -> np.ndarray:
    """`forward` (2 or 3 coordinates) as a unit vector in the ground plane (3,)."""
    vector = np.zeros(3)
    given = np.asarray(forward, dtype=float).ravel()
    if given.shape not in ((2,), (3,)) or not np.all(np.isfinite(given)):
        raise ValidationError(f"{field} must be a finite vector of 2 or 3 coordinates; got {forward!r}")
    vector[:2] = given[:2]
    length = np.linalg.norm(vector)
    if length < 1e-12:
        raise ValidationError(f"{field} must have a direction in the ground plane (x, y); got {forward!r}")
    return vector / length


def stride_speed(motion: Motion, *, forward, contact: float = CONTACT) -> float:
    """How fast a clip played in place pushes the ground back along `forward` (units per second):
    in each frame, the points within `contact` times the clip's height of that frame's lowest
    point (what touches the ground), their velocity along `forward` (central differences); the
    median over those points and frames, negated. An object moved forwards at that speed keeps
    those points still on the ground. z is up (a mesh in flockkit's axes)."""
    if not isinstance(motion, Motion) or motion.dims != 3 or motion.n_frames < 3:
        raise ValidationError("stride_speed needs a 3D flockkit.Motion (z up) of at least 3 frames")
    contact = number(contact, "stride_speed: contact", minimum=0, strict=True)
    direction = _ground_direction(forward, "stride_speed: forward")
    heights = motion.positions[..., 2]
    band = contact * float(np.ptp(heights))
    low = heights <= heights.min(axis=1, keepdims=True) + band
    along = np.gradient(motion.positions @ direction, motion.dt, axis=0)
    inner = np.zeros_like(low)
    inner[1:-1] = low[1:-1]  # one-sided differences at the ends are not a foot's speed
    return float(-np.median(along[inner]))
