"""Motion, Configuration, State and the configuration-space frame (paper 000, section 4.1).

Conventions
-----------
Positions are (T, N, D) arrays with D in {2, 3}; `dt` is the time between frames in seconds.
The velocity of an agent at frame t is the velocity that carries it to frame t + 1,
``(x[t + 1] - x[t]) / dt``; at the last frame, where there is no next frame, it is the velocity it
arrived with, ``(x[-1] - x[-2]) / dt``. A one-frame motion has zero velocities.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import attrs
import numpy as np

from . import _npzfile, rigid
from ._arrays import check_agent_array, check_finite, readonly_float, readonly_int, readonly_mapping
from .errors import FileFormatError, ValidationError
from .validate import allocation, integer, number
from .validate import dims as validate_dims

__all__ = [
    "Motion",
    "Configuration",
    "State",
    "ConfigurationFrame",
    "Alignment",
    "DEFAULT_UP",
    "heading_axes",
    "random_flock",
]

#: The world up direction used for 3D configuration frames unless another is given (z up).
DEFAULT_UP = (0.0, 0.0, 1.0)

MOTION_FORMAT_VERSION = 1

# Below this fraction of the mean agent speed the mean velocity is treated as zero (agents that
# cancel each other out give no heading), and below this sine the heading is treated as parallel
# to up. Our choice: far above float64 rounding (1e-16), far below any heading a capture resolves.
_DEGENERATE = 1e-6


def _field(name: str):
    return attrs.field(converter=functools.partial(readonly_float, field=name))


def _arrays_equal(a: Mapping, b: Mapping) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@attrs.frozen(kw_only=True, eq=False)
class ConfigurationFrame:
    """A rigid world-to-configuration-space transform: ``local = (world - origin) @ axes.T``.

    Attributes
    ----------
    origin : ndarray, shape (D,)
        The center of mass, in world coordinates.
    axes : ndarray, shape (D, D)
        Orthonormal rows: the configuration x, y (and z) axes in world coordinates; det = +1.
    """

    origin: np.ndarray = _field("ConfigurationFrame.origin")
    axes: np.ndarray = _field("ConfigurationFrame.axes")

    def __attrs_post_init__(self):
        _check_rotation(self.axes, "ConfigurationFrame.axes")
        if self.origin.shape != (self.axes.shape[0],):
            raise ValidationError(
                f"ConfigurationFrame.origin must have shape ({self.axes.shape[0]},); got {self.origin.shape}"
            )
        check_finite(self.origin, field="ConfigurationFrame.origin")

    def to_local(self, points) -> np.ndarray:
        """World points (..., D) to configuration coordinates."""
        return (np.asarray(points, dtype=np.float64) - self.origin) @ self.axes.T

    def to_world(self, points) -> np.ndarray:
        """Configuration coordinates (..., D) to world points."""
        return np.asarray(points, dtype=np.float64) @ self.axes + self.origin

    def vectors_to_local(self, vectors) -> np.ndarray:
        """World directions (..., D), such as velocities, to configuration coordinates (no translation)."""
        return np.asarray(vectors, dtype=np.float64) @ self.axes.T


def _check_rotation(rotation: np.ndarray, field: str) -> None:
    d = rotation.shape[0] if rotation.ndim == 2 else -1
    if d not in (2, 3) or rotation.shape != (d, d):
        raise ValidationError(f"{field} must have shape (D, D) with D in {{2, 3}}; got {rotation.shape}")
    check_finite(rotation, field=field)
    if not np.allclose(rotation @ rotation.T, np.eye(d), atol=1e-9) or np.linalg.det(rotation) < 0:
        raise ValidationError(f"{field} must be a proper rotation (orthonormal, det = +1)")


@attrs.frozen(kw_only=True, eq=False)
class Alignment:
    """How configuration `b` best lies on configuration `a`: what a metric's compare(a, b) returns.

    ``a.positions[i] ~= rotation @ b.positions[assignment[i]] + translation``.

    Attributes
    ----------
    distance : float
        The metric's value, >= 0 (for ``icp-hungarian``: E of paper 000 section 4.2, the mean
        squared distance after alignment).
    assignment : ndarray of int, shape (N,)
        A permutation: agent i of `a` takes slot ``assignment[i]`` of `b`.
    rotation : ndarray, shape (D, D)
        A proper rotation (det = +1): no reflection, no scaling.
    translation : ndarray, shape (D,)
    """

    distance: float = attrs.field(converter=lambda v: number(v, "Alignment.distance", minimum=0))
    assignment: np.ndarray = attrs.field(
        converter=lambda value: readonly_int(value, field="Alignment.assignment", dtype=np.intp)
    )
    rotation: np.ndarray = _field("Alignment.rotation")
    translation: np.ndarray = _field("Alignment.translation")

    def __attrs_post_init__(self):
        if not np.isfinite(self.distance) or self.distance < 0:
            raise ValidationError(f"Alignment.distance must be a finite number >= 0; got {self.distance}")
        n = self.assignment.shape[0] if self.assignment.ndim == 1 else -1
        if n < 1 or not np.array_equal(np.sort(self.assignment), np.arange(n)):
            raise ValidationError(f"Alignment.assignment must be a permutation of 0..N-1; got {self.assignment}")
        _check_rotation(self.rotation, "Alignment.rotation")
        if self.translation.shape != (self.rotation.shape[0],):
            raise ValidationError(
                f"Alignment.translation must have shape ({self.rotation.shape[0]},); got {self.translation.shape}"
            )
        check_finite(self.translation, field="Alignment.translation")

    def __eq__(self, other):
        if not isinstance(other, Alignment):
            return NotImplemented
        return (
            self.distance == other.distance
            and np.array_equal(self.assignment, other.assignment)
            and np.array_equal(self.rotation, other.rotation)
            and np.array_equal(self.translation, other.translation)
        )

    __hash__ = None

    def transform(self, points) -> np.ndarray:
        """Points (..., D) of `b`'s world into `a`'s: ``points @ rotation.T + translation``."""
        return rigid.apply(self.rotation, self.translation, points)

    def inverse(self) -> Alignment:
        """The alignment of `a` onto `b` (same distance): what compare(b, a) would ideally return."""
        assignment = np.empty_like(self.assignment)
        assignment[self.assignment] = np.arange(len(self.assignment))
        rotation, translation = rigid.invert(self.rotation, self.translation)
        return Alignment(distance=self.distance, assignment=assignment, rotation=rotation, translation=translation)

    def residual(self, a: Configuration, b: Configuration) -> float:
        """Mean squared distance between `a`'s positions and `b`'s, aligned and reassigned."""
        moved = self.transform(b.positions[self.assignment])
        return float(np.mean(np.sum((a.positions - moved) ** 2, axis=1)))


def heading_axes(velocities, *, up=DEFAULT_UP) -> np.ndarray:
    """The axes of ``Configuration(...).frame(up=up)`` for many configurations at once.

    `velocities` has shape (..., N, D); the result (..., D, D) holds each frame's rows x, y(, z),
    with the fallbacks that `Configuration.frame` describes. Metrics that start from the
    configuration-space alignment of thousands of configurations use it."""
    velocities = np.asarray(velocities, dtype=float)
    if velocities.ndim < 2 or velocities.shape[-1] not in (2, 3):
        raise ValidationError(f"heading_axes needs velocities of shape (..., N, 2 or 3); got {velocities.shape}")
    d = velocities.shape[-1]
    mean = velocities.mean(axis=-2)
    mean_speed = np.linalg.norm(velocities, axis=-1).mean(axis=-1)
    norm = np.linalg.norm(mean, axis=-1)
    ok = (norm > 0) & (norm > _DEGENERATE * mean_speed)
    # rescaled first: tiny norms lose precision
    scaled = mean / np.where(ok, np.abs(mean).max(axis=-1), 1.0)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):  # the degenerate ones are replaced
        x = np.where(ok[..., None], scaled / np.linalg.norm(scaled, axis=-1, keepdims=True), np.eye(d)[0])
    if d == 2:
        return np.stack([x, np.stack([-x[..., 1], x[..., 0]], axis=-1)], axis=-2)
    up = readonly_float(up, field="up")
    if up.shape != (3,) or not np.all(np.isfinite(up)) or not np.linalg.norm(up) > 0:
        raise ValidationError(f"up must be a finite, non-zero 3-vector; got {up!r}")
    y = np.cross(up / np.linalg.norm(up), x)
    # heading parallel to up: use the world axis least aligned with the heading instead
    parallel = np.linalg.norm(y, axis=-1) <= _DEGENERATE
    y = np.where(parallel[..., None], np.cross(np.eye(3)[np.argmin(np.abs(x), axis=-1)], x), y)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-2)


class _OneInstant:
    """Counts shared by the one-instant types, whose positions are (N, D)."""

    @property
    def n_agents(self) -> int:
        """N, the number of agents."""
        return self.positions.shape[0]

    @property
    def dims(self) -> int:
        """D, the number of dimensions (2 or 3)."""
        return self.positions.shape[1]


@attrs.frozen(kw_only=True, eq=False)
class Configuration(_OneInstant):
    """The agents of a group at one instant.

    Parameters
    ----------
    positions, velocities : array_like, shape (N, D)
        World positions and velocities; D in {2, 3}; finite.
    """

    positions: np.ndarray = _field("Configuration.positions")
    velocities: np.ndarray = _field("Configuration.velocities")

    def __attrs_post_init__(self):
        check_agent_array(self.positions, field="Configuration.positions")
        check_agent_array(self.velocities, field="Configuration.velocities", shape=self.positions.shape)

    def __eq__(self, other):
        if not isinstance(other, Configuration):
            return NotImplemented
        return np.array_equal(self.positions, other.positions) and np.array_equal(self.velocities, other.velocities)

    __hash__ = None

    def center_of_mass(self) -> np.ndarray:
        """The mean position, shape (D,)."""
        return self.positions.mean(axis=0)

    def frame(self, *, up=DEFAULT_UP) -> ConfigurationFrame:
        """The configuration-space transform of paper 000 section 4.1.

        The origin is the center of mass and the x axis points along the mean velocity. In 2D the
        y axis is x rotated by +90 degrees. In 3D, y = up x x (normalized) and z = x x y, so z is
        `up` made perpendicular to the heading.

        Fallbacks, so that every configuration has a frame:

        - if the mean velocity is zero or shorter than 1e-6 times the mean agent speed (a group at
          rest, or agents cancelling each other out), the x axis is the world x axis;
        - in 3D, if the heading is parallel to `up` (sine of the angle below 1e-6), `up` is
          replaced by the world axis least aligned with the heading (lowest index on ties).
        """
        return ConfigurationFrame(origin=self.center_of_mass(), axes=heading_axes(self.velocities, up=up))


@attrs.frozen(kw_only=True, eq=False)
class State(_OneInstant):
    """What a behavior model needs to continue a simulation.

    Parameters
    ----------
    positions, velocities : array_like, shape (N, D)
        As in Configuration.
    extra : mapping of str to array_like (N, D), optional
        Model arrays carried between steps, such as the boids ``wander`` contribution. Names are
        Python identifiers; each array has the shape of `positions` (default: none).
    """

    positions: np.ndarray = _field("State.positions")
    velocities: np.ndarray = _field("State.velocities")
    extra: Mapping[str, np.ndarray] = attrs.field(
        factory=dict, converter=functools.partial(readonly_mapping, field="State.extra")
    )

    def __attrs_post_init__(self):
        check_agent_array(self.positions, field="State.positions")
        check_agent_array(self.velocities, field="State.velocities", shape=self.positions.shape)
        for name, array in self.extra.items():
            check_agent_array(array, field=f"State.extra[{name!r}]", shape=self.positions.shape)

    def __eq__(self, other):
        if not isinstance(other, State):
            return NotImplemented
        return (
            np.array_equal(self.positions, other.positions)
            and np.array_equal(self.velocities, other.velocities)
            and _arrays_equal(self.extra, other.extra)
        )

    __hash__ = None

    def configuration(self) -> Configuration:
        return Configuration(positions=self.positions, velocities=self.velocities)


@attrs.frozen(kw_only=True, eq=False)
class Motion:
    """The trajectories of a group: positions (T, N, D) sampled every `dt` seconds.

    Indexing with a slice (``motion[10:20]``, ``motion[::2]``) returns a Motion of those frames; a
    step k multiplies `dt` by k.

    Parameters
    ----------
    positions : array_like, shape (T, N, D)
        T >= 1 frames, N >= 1 agents, D in {2, 3}; finite.
    dt : float
        Seconds between frames, > 0.
    channels : mapping of str to array_like (T, N, D), optional
        Named per-agent, per-frame model arrays, such as the boids ``wander`` contribution
        (default: none).
    """

    positions: np.ndarray = _field("Motion.positions")
    dt: float = attrs.field(converter=functools.partial(number, field="Motion.dt", minimum=0, strict=True))
    channels: Mapping[str, np.ndarray] = attrs.field(
        factory=dict, converter=functools.partial(readonly_mapping, field="Motion.channels")
    )

    def __attrs_post_init__(self):
        shape = self.positions.shape
        if self.positions.ndim != 3 or shape[2] not in (2, 3) or shape[0] < 1 or shape[1] < 1:
            raise ValidationError(
                f"Motion.positions must have shape (T, N, D) with T >= 1, N >= 1 and D in {{2, 3}}; got {shape}"
            )
        check_finite(self.positions, field="Motion.positions")
        for name, array in self.channels.items():
            field = f"Motion.channels[{name!r}]"
            if array.shape != shape:
                raise ValidationError(f"{field} must have the shape of positions {shape}; got {array.shape}")
            check_finite(array, field=field)

    @classmethod
    def _adopt(cls, positions: np.ndarray, dt: float) -> Motion:
        """A Motion that takes `positions` (a float64 array flockkit just made and holds nowhere
        else) without copying it: made read-only and checked as the constructor checks. Synthesis
        writes hundreds of megabytes, and a copy of that costs more than computing it."""
        if not isinstance(positions, np.ndarray) or positions.dtype != np.float64:
            return cls(positions=positions, dt=dt)
        motion = object.__new__(cls)
        positions.setflags(write=False)
        object.__setattr__(motion, "positions", positions)
        object.__setattr__(motion, "dt", number(dt, "Motion.dt", minimum=0, strict=True))
        object.__setattr__(motion, "channels", readonly_mapping({}, field="Motion.channels"))
        motion.__attrs_post_init__()
        return motion

    def __eq__(self, other):
        if not isinstance(other, Motion):
            return NotImplemented
        return (
            self.dt == other.dt
            and np.array_equal(self.positions, other.positions)
            and _arrays_equal(self.channels, other.channels)
        )

    __hash__ = None

    def __repr__(self) -> str:
        names = ", ".join(self.channels) or "none"
        return (
            f"Motion({self.n_frames} frames x {self.n_agents} agents in {self.dims}D, dt={self.dt:g} s, "
            f"channels: {names})"
        )

    @property
    def n_frames(self) -> int:
        """T, the number of frames."""
        return self.positions.shape[0]

    @property
    def n_agents(self) -> int:
        """N, the number of agents."""
        return self.positions.shape[1]

    @property
    def dims(self) -> int:
        """D, the number of dimensions (2 or 3)."""
        return self.positions.shape[2]

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last: (T - 1) * dt."""
        return (self.n_frames - 1) * self.dt

    def velocities(self) -> np.ndarray:
        """Velocities (T, N, D) by finite differences (see the module docstring for the convention)."""
        if self.n_frames == 1:
            return np.zeros_like(self.positions)
        steps = np.diff(self.positions, axis=0) / self.dt
        return np.concatenate([steps, steps[-1:]], axis=0)

    def center_of_mass(self) -> np.ndarray:
        """Mean position per frame, shape (T, D)."""
        return self.positions.mean(axis=1)

    def _frame_index(self, t) -> int:
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)):
            raise ValidationError(f"frame index must be an integer; got {t!r}")
        if not -self.n_frames <= t < self.n_frames:
            raise ValidationError(f"frame index {t} is out of range for a motion of {self.n_frames} frames")
        return int(t) % self.n_frames

    def _velocity_at(self, t: int) -> np.ndarray:
        if self.n_frames == 1:
            return np.zeros_like(self.positions[0])
        a = min(t, self.n_frames - 2)
        return (self.positions[a + 1] - self.positions[a]) / self.dt

    def configuration(self, t: int) -> Configuration:
        """The configuration at frame `t` (negative counts from the end)."""
        t = self._frame_index(t)
        return Configuration(positions=self.positions[t], velocities=self._velocity_at(t))

    def state(self, t: int) -> State:
        """The state at frame `t` (negative counts from the end), channels as `extra`."""
        t = self._frame_index(t)
        return State(
            positions=self.positions[t],
            velocities=self._velocity_at(t),
            extra={name: array[t] for name, array in self.channels.items()},
        )

    def __getitem__(self, frames) -> Motion:
        if not isinstance(frames, slice):
            raise TypeError("index a Motion with a slice of frames; use state(t) or configuration(t) for one frame")
        if frames.step == 0:
            raise ValidationError("Motion slices need a positive step; got 0")
        start, stop, step = frames.indices(self.n_frames)
        if step < 1:
            raise ValidationError(f"Motion slices need a positive step; got {step}")
        selected = range(start, stop, step)
        if len(selected) == 0:
            raise ValidationError(f"slice {frames} selects no frames of a motion of {self.n_frames} frames")
        return Motion(
            positions=self.positions[frames],
            dt=self.dt * step,
            channels={name: array[frames] for name, array in self.channels.items()},
        )

    def _to_arrays(self) -> dict[str, np.ndarray]:
        """Positions and channels as the named arrays of a flockkit file (motion and graph files)."""
        return {"positions": self.positions, **{f"channel.{name}": array for name, array in self.channels.items()}}

    @classmethod
    def _from_arrays(cls, arrays: Mapping[str, np.ndarray], dt) -> Motion:
        """The inverse of :meth:`_to_arrays`; KeyError if positions are missing, ValidationError if invalid."""
        channels = {name.removeprefix("channel."): a for name, a in arrays.items() if name.startswith("channel.")}
        for name, array in (("positions", arrays["positions"]), *channels.items()):
            if array.dtype.kind != "f":
                raise ValidationError(f"{name} must hold floating-point numbers; got {array.dtype}")
        return cls(positions=arrays["positions"], dt=dt, channels=channels)

    def save(self, path) -> None:
        """Write the motion to `path` (.npz of plain arrays with JSON metadata; atomic)."""
        _npzfile.write(
            path, kind="motion", version=MOTION_FORMAT_VERSION, arrays=self._to_arrays(), metadata={"dt": self.dt}
        )

    @classmethod
    def load(cls, path) -> Motion:
        """Read a motion written by :meth:`save`; raises FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(path, kind="motion", versions=(MOTION_FORMAT_VERSION,))
        if "positions" not in arrays:
            raise FileFormatError(f"{path}: motion file has no 'positions' array")
        try:
            return cls._from_arrays(arrays, header.get("dt"))
        except ValidationError as exc:
            raise FileFormatError(f"{path}: invalid motion: {exc}") from None


def random_flock(
    *, n_agents: int, dims: int = 2, rng: np.random.Generator, spacing: float = 1.0, speed: float = 1.0
) -> State:
    """A random flock, the documented start of :func:`simulate`.

    Positions are uniform in a disc (2D) or ball (3D) around the origin whose area (volume) is
    ``n_agents * spacing**dims``, so neighbors are about `spacing` apart. All agents head roughly
    the same way: a common direction, uniform at random, plus independent Gaussian noise of
    standard deviation 0.2 per component, normalized and scaled to `speed`. No model arrays
    (``extra`` is empty), so a model starts its own (boids: zero wander).
    """
    n_agents = integer(n_agents, "n_agents", minimum=1)
    dims = validate_dims(dims)
    spacing = number(spacing, "spacing", minimum=0, strict=True)
    speed = number(speed, "speed", minimum=0, strict=True)
    allocation(3 * n_agents * dims, f"a random flock of {n_agents} agents")
    unit_ball = math.pi if dims == 2 else 4.0 * math.pi / 3.0
    radius = spacing * (n_agents / unit_ball) ** (1.0 / dims)
    directions = rng.standard_normal((n_agents, dims))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    positions = directions * radius * rng.random((n_agents, 1)) ** (1.0 / dims)
    heading = rng.standard_normal(dims)
    heading /= np.linalg.norm(heading)
    headings = heading + 0.2 * rng.standard_normal((n_agents, dims))
    velocities = speed * headings / np.linalg.norm(headings, axis=1, keepdims=True)
    return State(positions=positions, velocities=velocities)
