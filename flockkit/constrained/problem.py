"""The constraints of paper 004 and the Problem that gathers them: an agent here at a time
(``PointConstraint``), a group's center there (``ComConstraint``), a group inside a shape
(``ShapeConstraint``), over a flock of a size, a duration and a frame rate.
"""

from __future__ import annotations

import functools

import attrs
import numpy as np

from .._arrays import check_finite, readonly_float
from ..errors import ValidationError
from ..regions import EXTENT, Region
from ..validate import allocation, integer, number

__all__ = ["PointConstraint", "ComConstraint", "ShapeConstraint", "Constraint", "Problem", "track_path"]

# The most frames a Problem may have: a day at the paper's 10 Hz (86 400 s), rounded up. Beyond it
# the sampler's Python loops over frames take hours before any result.
MAX_FRAMES = 1_000_000
# The default Problem.keyframed_weight: on come-from-behind (seeds 1-5) the free agents' median KS p
# rose from 4.9e-37 at 1 to 2.2e-9 at 0.25 and no further below it, while the keyframed runner's own
# log g kept falling (-22.0 at 1, -54.5 at 0.25, -64.0 at 0.05); one-agent passes at every weight
# (bench/README.md, "keyframed weight").
KEYFRAMED_WEIGHT = 0.25


def _time(value, *, field: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValidationError(f"{field} must be a number of seconds >= 0; got {value!r}") from None
    if not np.isfinite(number) or number < 0:
        raise ValidationError(f"{field} must be a finite number of seconds >= 0; got {value!r}")
    return number


def _required_vector(value, *, field: str):
    if value is None:
        raise ValidationError(f"{field} is required: a point of shape (2,) or (3,)")
    return _vector(value, field=field)


def _vector(value, *, field: str):
    if value is None:
        return None
    array = readonly_float(value, field=field)
    if array.shape not in ((2,), (3,)):
        raise ValidationError(f"{field} must have shape (2,) or (3,); got {array.shape}")
    check_finite(array, field=field)
    return array


def _agents(value, *, field: str):
    if value is None:
        return None
    try:
        agents = tuple(value)
    except TypeError:
        raise ValidationError(
            f"{field} must be None (all agents) or a sequence of agent indices; got {value!r}"
        ) from None
    if (
        not agents
        or any(isinstance(a, bool) or not isinstance(a, (int, np.integer)) or a < 0 for a in agents)
        or len(set(agents)) != len(agents)
    ):
        raise ValidationError(f"{field} must be a non-empty sequence of distinct agent indices >= 0; got {value!r}")
    return tuple(int(a) for a in agents)


def _agent(value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValidationError(f"PointConstraint.agent must be an agent index >= 0; got {value!r}")
    return int(value)


@attrs.frozen(kw_only=True, eq=False)
class PointConstraint:
    """Agent `agent` passes through `position` at `time` seconds (exactly, in every sample).

    `velocity` (shape (D,)) is only a hint for the initial trajectories; left out, it is inferred
    from the B-spline through the agent's other point constraints (see Problem).
    """

    agent: int = attrs.field(converter=_agent)
    time: float = attrs.field(converter=functools.partial(_time, field="PointConstraint.time"))
    position: np.ndarray = attrs.field(converter=functools.partial(_required_vector, field="PointConstraint.position"))
    velocity: np.ndarray | None = attrs.field(
        default=None, converter=functools.partial(_vector, field="PointConstraint.velocity")
    )

    def __attrs_post_init__(self):
        _same_dims(self, "position", "velocity")


@attrs.frozen(kw_only=True, eq=False)
class ComConstraint:
    """The center of mass of `agents` (None: all) is at `position` at `time` seconds.

    A Gaussian term of the objective (standard deviation ``Problem.sigma_com``); a solution meets
    it within 3 sigma_com. ``solve`` meets it exactly at its aim (``flockkit.constrained.com_aims``: for
    a track of them, the point within 2.7 sigma_com that lets the group's path ask least of the
    model), then keeps it by the objective; a small sigma_com holds it where it is. `velocity` as
    for PointConstraint.
    """

    agents: tuple[int, ...] | None = attrs.field(
        default=None, converter=functools.partial(_agents, field="ComConstraint.agents")
    )
    time: float = attrs.field(converter=functools.partial(_time, field="ComConstraint.time"))
    position: np.ndarray = attrs.field(converter=functools.partial(_required_vector, field="ComConstraint.position"))
    velocity: np.ndarray | None = attrs.field(
        default=None, converter=functools.partial(_vector, field="ComConstraint.velocity")
    )

    def __attrs_post_init__(self):
        _same_dims(self, "position", "velocity")


@attrs.frozen(kw_only=True, eq=False)
class ShapeConstraint:
    """Every agent of `agents` (None: all) lies inside `shape` at `time` seconds.

    `shape` is a Polygon (2D: a triangle or any simple polygon), or a Box or Ball (2D or 3D).
    `velocity` (shape (D,)), the group's velocity there, is required: it orients the flock the
    initial trajectories place in the shape.
    """

    agents: tuple[int, ...] | None = attrs.field(
        default=None, converter=functools.partial(_agents, field="ShapeConstraint.agents")
    )
    time: float = attrs.field(converter=functools.partial(_time, field="ShapeConstraint.time"))
    shape: Region = attrs.field()
    velocity: np.ndarray = attrs.field(
        default=None, converter=functools.partial(_vector, field="ShapeConstraint.velocity")
    )

    def __attrs_post_init__(self):
        if not isinstance(self.shape, Region):
            raise ValidationError(
                f"ShapeConstraint.shape must be a flockkit.Polygon, Box or Ball; got {type(self.shape).__name__}"
            )
        if self.velocity is None:
            raise ValidationError(
                "ShapeConstraint.velocity is required (shape (D,)): the flock's velocity inside the shape"
            )
        if self.velocity.shape[0] != self.shape.dims:
            raise ValidationError(
                f"ShapeConstraint.velocity has {self.velocity.shape[0]} components but the shape is {self.shape.dims}D"
            )


Constraint = PointConstraint | ComConstraint | ShapeConstraint


def _same_dims(constraint, first: str, second: str) -> None:
    a, b = getattr(constraint, first), getattr(constraint, second)
    if b is not None and a.shape != b.shape:
        name = type(constraint).__name__
        raise ValidationError(f"{name}.{second} must have the shape of {name}.{first}, {a.shape}; got {b.shape}")


def _constraints(value) -> tuple:
    try:
        items = tuple(value)
    except TypeError:
        raise ValidationError(
            f"Problem.constraints must be a sequence of constraints; got {type(value).__name__}"
        ) from None
    for index, item in enumerate(items):
        if not isinstance(item, (PointConstraint, ComConstraint, ShapeConstraint)):
            raise ValidationError(
                f"Problem.constraints[{index}] must be a PointConstraint, ComConstraint or ShapeConstraint; got "
                f"{type(item).__name__}"
            )
    return items


def _regions(value) -> tuple:
    try:
        items = tuple(value)
    except TypeError:
        raise ValidationError(f"Problem.obstacles must be a sequence of regions; got {type(value).__name__}") from None
    for index, item in enumerate(items):
        if not isinstance(item, Region):
            raise ValidationError(
                f"Problem.obstacles[{index}] must be a flockkit.Ball, Box or Polygon; got {type(item).__name__}"
            )
    return items


def track_path(times, positions):
    """The B-spline through a track's positions at its times (``make_interp_spline``: linear
    through two, quadratic through three, and through four or more the natural cubic, which
    bends least): the path the initial trajectories follow, and whose derivative gives a track's
    missing velocities.

    Natural, not scipy's default not-a-knot ends: those bend a path hardest at its ends, so an
    agent meets its first keyframe faster and more turned than it need, and pays for it in every
    frame before (bench/README.md compares the two on the example scenarios). Through three
    positions, the natural cubic does no better than the quadratic."""
    from scipy.interpolate import make_interp_spline

    k = min(3, len(times) - 1)
    return make_interp_spline(
        np.asarray(times, dtype=float), np.asarray(positions, dtype=float), k=k, bc_type="natural" if k == 3 else None
    )


def _track_key(constraint):
    if isinstance(constraint, PointConstraint):
        return ("point", constraint.agent)
    if isinstance(constraint, ComConstraint):
        return ("com", constraint.agents)
    return None


@attrs.frozen(kw_only=True, eq=False)
class Problem:
    """A constrained animation problem (paper 004): who must be where, when.

    Parameters
    ----------
    n_agents, dims : int
        Flock size (>= 1) and 2 or 3 dimensions.
    dt, duration : float
        Seconds per frame and in all: the solution has ``round(duration / dt) + 1`` frames, and a
        constraint at time t applies to frame ``round(t / dt)``.
    constraints : sequence of PointConstraint, ComConstraint, ShapeConstraint
        Held here with every velocity filled in: a point (or COM) constraint without one takes
        the derivative of the B-spline (``scipy.interpolate.make_interp_spline``, cubic where
        there are four or more) through the agent's (or the subset's) constraints; a constraint
        that has no other to fit with needs its velocity given.
    obstacles : sequence of regions
        Static obstacles, passed to the behavior model.
    flocks : int
        The preferred number of flocks F_c of the objective's g_f term.
    sigma_com, shape_weight, flock_weight : float
        The paper's sigma_com = 0.1, c_S = 10 and c_F = 1000.
    visibility : float
        Agents closer than this see each other when counting flocks (boids' perception radius).
    clearance : float
        How far (length units, >= 0) the initial trajectories keep agents from the obstacles'
        surfaces: blending simulations and moving groups onto their paths can carry an agent into
        an obstacle, where a model's avoidance is at its strongest (0: not kept).
    follow : str
        How the initial trajectories move unconstrained agents: "nearest" (with the constrained
        agent nearest to them, smoother) or "random" (with a constrained agent drawn at random,
        livelier), as section 3.3.1 offers.
    keyframed_weight : float
        The weight (>= 0) in the objective of the behavior's plausibility terms of agents with a
        point constraint: their paths are the director's, so where they move unlike the model
        the rest of the flock should still move like it, not arrange itself to explain them. With
        paper 004's weight 1, the most plausible motion as a whole tilts the free flock towards
        the keyframed agents (a free flock's impulses then fail a KS test against a forward
        simulation's); the default was chosen by measurement (bench/README.md, "keyframed
        weight"). Applied where the behavior declares ``Capabilities(residuals=True)`` (its terms
        split by agent); other models weigh every agent 1.
    """

    n_agents: int = attrs.field(converter=lambda v: integer(v, "Problem.n_agents", minimum=1))
    dims: int = attrs.field(default=2, converter=lambda v: integer(v, "Problem.dims", minimum=2))
    dt: float = attrs.field(
        default=0.1, converter=functools.partial(number, field="Problem.dt", minimum=0, strict=True)
    )
    duration: float = attrs.field(converter=functools.partial(number, field="Problem.duration", minimum=0, strict=True))
    constraints: tuple = attrs.field(default=(), converter=_constraints)
    obstacles: tuple = attrs.field(default=(), converter=_regions)
    flocks: int = attrs.field(default=1, converter=lambda v: integer(v, "Problem.flocks", minimum=1))
    sigma_com: float = attrs.field(
        default=0.1, converter=functools.partial(number, field="Problem.sigma_com", minimum=0, strict=True)
    )
    shape_weight: float = attrs.field(
        default=10.0, converter=functools.partial(number, field="Problem.shape_weight", minimum=0, strict=True)
    )
    flock_weight: float = attrs.field(
        default=1000.0, converter=functools.partial(number, field="Problem.flock_weight", minimum=0, strict=True)
    )
    visibility: float = attrs.field(
        default=3.0, converter=functools.partial(number, field="Problem.visibility", minimum=0, strict=True)
    )
    clearance: float = attrs.field(
        default=0.5, converter=functools.partial(number, field="Problem.clearance", minimum=0, maximum=EXTENT)
    )
    follow: str = attrs.field(default="nearest")
    keyframed_weight: float = attrs.field(
        default=KEYFRAMED_WEIGHT,
        converter=functools.partial(number, field="Problem.keyframed_weight", minimum=0),
    )

    def __attrs_post_init__(self):
        if self.dims not in (2, 3):
            raise ValidationError(f"Problem.dims must be 2 or 3; got {self.dims!r}")
        if not self.duration / self.dt < MAX_FRAMES:
            raise ValidationError(
                f"Problem: duration {self.duration:g} s at dt = {self.dt:g} s is {self.duration / self.dt:.3g} "
                "frames; at most "
                f"{MAX_FRAMES} are supported (the sampler holds and simulates every frame)"
            )
        frames = self.duration / self.dt + 1
        allocation(self.n_agents * frames * self.dims, f"Problem: {self.n_agents} agents over {frames:.0f} frames")
        if not isinstance(self.follow, str) or self.follow not in ("nearest", "random"):
            raise ValidationError(f"Problem.follow must be 'nearest' or 'random'; got {self.follow!r}")
        for index, constraint in enumerate(self.constraints):
            self._check_constraint(index, constraint)
        for index, obstacle in enumerate(self.obstacles):
            if obstacle.dims != self.dims:
                raise ValidationError(f"Problem.obstacles[{index}] is {obstacle.dims}D in a {self.dims}D problem")
        object.__setattr__(self, "constraints", self._with_velocities())

    @property
    def n_frames(self) -> int:
        """T, the number of frames: duration / dt + 1."""
        return round(self.duration / self.dt) + 1

    def agent_weights(self) -> np.ndarray:
        """(N,) the weight of each agent's plausibility terms in the objective: keyframed_weight
        for agents with a point constraint, 1 for the others."""
        weights = np.ones(self.n_agents)
        weights[[c.agent for c in self.constraints if isinstance(c, PointConstraint)]] = self.keyframed_weight
        return weights

    def frame(self, time: float) -> int:
        """The frame a constraint at `time` seconds applies to."""
        return round(time / self.dt)

    def agents_of(self, constraint) -> tuple[int, ...]:
        """The agents a constraint is about (all of them for agents=None)."""
        if isinstance(constraint, PointConstraint):
            return (constraint.agent,)
        return tuple(range(self.n_agents)) if constraint.agents is None else constraint.agents

    @property
    def tracks(self) -> tuple[tuple, ...]:
        """Point constraints of one agent, and COM constraints of one subset, each in time order."""
        grouped: dict = {}
        for constraint in self.constraints:
            key = _track_key(constraint)
            if key is not None:
                grouped.setdefault(key, []).append(constraint)
        return tuple(tuple(sorted(track, key=lambda c: c.time)) for track in grouped.values())

    def _check_constraint(self, index, constraint):
        where = f"Problem.constraints[{index}] ({type(constraint).__name__} at t={constraint.time:g})"
        if constraint.time > self.duration + 1e-9 * self.dt:
            raise ValidationError(f"{where}: time is after the end of the problem, {self.duration:g} s")
        dims = constraint.shape.dims if isinstance(constraint, ShapeConstraint) else constraint.position.shape[0]
        if dims != self.dims:
            raise ValidationError(f"{where} is {dims}D in a {self.dims}D problem")
        bad = [a for a in self.agents_of(constraint) if a >= self.n_agents]
        if bad:
            raise ValidationError(
                f"{where}: agent {bad[0]} does not exist; the problem has agents 0 to {self.n_agents - 1}"
            )

    def _with_velocities(self) -> tuple:
        filled = {}
        for track in self.tracks:
            frames = [self.frame(c.time) for c in track]
            if len(set(frames)) != len(frames):
                repeated = next(f for f in frames if frames.count(f) > 1)
                raise ValidationError(
                    f"two {type(track[0]).__name__}s on the same agents at frame {repeated} (t={repeated * self.dt:g} "
                    "s)"
                )
            missing = [c for c in track if c.velocity is None]
            if not missing:
                continue
            if len(track) == 1:
                c = track[0]
                what = (
                    f"point constraint on agent {c.agent}"
                    if isinstance(c, PointConstraint)
                    else f"COM constraint on agents {c.agents or 'all'}"
                )
                raise ValidationError(
                    f"the only {what} (t={c.time:g}) has no path to infer its velocity from; give it a velocity"
                )
            spline = track_path([c.time for c in track], [c.position for c in track]).derivative()
            for c in missing:
                filled[id(c)] = attrs.evolve(c, velocity=spline(c.time))
        return tuple(filled.get(id(c), c) for c in self.constraints)
