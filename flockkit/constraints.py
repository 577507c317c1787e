"""Regions of space (obstacles for behavior models, regions for walks, shapes for constraints),
the constraints of paper 004 and the Problem that gathers them.

Each region (a ``Region``: ``Ball``, ``Box`` or ``Polygon``) offers ``contains(points)``,
``signed_distance(points)`` (negative inside) and ``surface_normal(points)`` (the outward unit
normal of the nearest boundary, the gradient of the signed distance), vectorized over points of
shape (M, D), and ``bounds()``, ``centroid()``, ``interior_point()`` and ``sample(count, rng)``,
so that callers never need to ask which kind of region they hold.
"""

from __future__ import annotations

import functools
import math

import attrs
import numpy as np

from ._arrays import check_finite, readonly_float
from .errors import ValidationError
from .validate import integer, number

__all__ = [
    "fence",
    "Ball",
    "Box",
    "Polygon",
    "Region",
    "PointConstraint",
    "ComConstraint",
    "ShapeConstraint",
    "Constraint",
    "Problem",
]


def _field(name: str):
    return attrs.field(converter=functools.partial(readonly_float, field=name))


# The most frames a Problem may have: a day at the paper's 10 Hz (86 400 s), rounded up. Beyond it
# the sampler's Python loops over frames take hours before any result.
MAX_FRAMES = 1_000_000

# Regions keep their coordinates within +-1e150 so that squared distances (areas, volumes) stay
# finite in float64, whose largest value is 1.8e308.
EXTENT = 1e150


def _check_extent(array: np.ndarray, field: str) -> None:
    check_finite(array, field=field)
    if np.any(np.abs(array) > EXTENT):
        raise ValidationError(f"{field} must lie within +-{EXTENT:g} (squared distances must stay finite); got {array}")


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors; vectors too short to normalize accurately (subnormal scale) become zero."""
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 1e-150)


class Region:
    """A region of space: the base of Ball, Box and Polygon.

    Subclasses define `dims`, `bounds()`, `centroid()` and `_distance_and_normal(points)`."""

    def _points(self, points) -> np.ndarray:
        points = readonly_float(points, field=f"points for a {type(self).__name__}")
        if points.ndim == 0 or points.shape[-1] != self.dims:
            raise ValidationError(
                f"points for a {self.dims}D {type(self).__name__} must have shape (..., {self.dims}); got "
                f"{points.shape}"
            )
        return points.reshape(-1, self.dims)

    def signed_distance(self, points) -> np.ndarray:
        """Distance from each point to the boundary, negative inside; shape points.shape[:-1]."""
        flat = self._points(points)
        distance, _ = self._distance_and_normal(flat)
        return distance.reshape(np.shape(points)[:-1])

    def surface_normal(self, points) -> np.ndarray:
        """Outward unit normal of the boundary nearest each point; shape points.shape."""
        _, normal = self._distance_and_normal(self._points(points))
        return normal.reshape(np.shape(points))

    def contains(self, points) -> np.ndarray:
        """Whether each point lies inside or on the boundary."""
        return self.signed_distance(points) <= 0

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The corners (lower, upper) of the smallest axis-aligned box holding the region."""
        raise NotImplementedError

    def centroid(self) -> np.ndarray:
        """The center of mass of the region's area (volume), shape (D,)."""
        raise NotImplementedError

    def interior_point(self) -> np.ndarray:
        """A point well inside the region (its centroid, where that is inside)."""
        return self.centroid()

    def outline(self) -> np.ndarray:
        """The region's outline in the x-y plane (its cross-section through the centroid in 3D) as
        (K, 2) vertices of a closed polygon, for drawing."""
        raise NotImplementedError

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """`count` points drawn uniformly inside the region, shape (count, D), by rejection from
        its bounding box. Raises ValidationError when the region fills too little of its box to
        sample (a sliver: under one draw in a million lands inside)."""
        count = integer(count, "count", minimum=0)
        lower, upper = self.bounds()
        points, drawn = [], 0
        while sum(len(p) for p in points) < count:
            # batches double, so that a sliver is refused after a few dozen batches, not thousands
            batch = rng.uniform(lower, upper, size=(max(4 * count + 16, drawn), self.dims))
            points.append(batch[self.contains(batch)])
            drawn += len(batch)
            if drawn > 1_000_000 and not sum(len(p) for p in points):
                raise ValidationError(
                    f"{type(self).__name__}: no sample in {drawn} draws fell inside; the region has (almost) no area"
                )
        return np.concatenate(points or [np.empty((0, self.dims))])[:count]


@attrs.frozen(kw_only=True, eq=False)
class Ball(Region):
    """A disc (2D) or sphere (3D).

    Parameters
    ----------
    center : array_like, shape (D,)
    radius : float, > 0
    """

    center: np.ndarray = _field("Ball.center")
    radius: float = attrs.field(
        converter=functools.partial(number, field="Ball.radius", minimum=0, strict=True, maximum=EXTENT)
    )

    def __attrs_post_init__(self):
        if self.center.shape not in ((2,), (3,)):
            raise ValidationError(f"Ball.center must have shape (2,) or (3,); got {self.center.shape}")
        _check_extent(self.center, "Ball.center")

    @property
    def dims(self) -> int:
        return self.center.shape[0]

    def bounds(self):
        return self.center - self.radius, self.center + self.radius

    def centroid(self):
        return np.array(self.center)

    def outline(self):
        angle = np.linspace(0.0, 2 * np.pi, 65)[:-1]
        return self.center[:2] + self.radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)

    def _distance_and_normal(self, points):
        offset = points - self.center
        distance = np.linalg.norm(offset, axis=1)
        normal = _unit(offset)
        normal[~normal.any(axis=1), 0] = 1.0  # at the center any direction is nearest; pick +x
        return distance - self.radius, normal


@attrs.frozen(kw_only=True, eq=False)
class Box(Region):
    """An axis-aligned rectangle (2D) or box (3D).

    Parameters
    ----------
    lower, upper : array_like, shape (D,)
        Opposite corners, lower < upper in every coordinate.
    """

    lower: np.ndarray = _field("Box.lower")
    upper: np.ndarray = _field("Box.upper")

    def __attrs_post_init__(self):
        if self.lower.shape not in ((2,), (3,)) or self.upper.shape != self.lower.shape:
            raise ValidationError(
                f"Box.lower and Box.upper must both have shape (2,) or (3,); got {self.lower.shape} and "
                f"{self.upper.shape}"
            )
        _check_extent(self.lower, "Box.lower")
        _check_extent(self.upper, "Box.upper")
        if not np.all(self.lower < self.upper):
            raise ValidationError(
                f"Box.lower must be below Box.upper in every coordinate; got {self.lower} and {self.upper}"
            )

    @property
    def dims(self) -> int:
        return self.lower.shape[0]

    def bounds(self):
        return np.array(self.lower), np.array(self.upper)

    def centroid(self):
        return (self.lower + self.upper) / 2

    def outline(self):
        (x0, y0), (x1, y1) = self.lower[:2], self.upper[:2]
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    def _distance_and_normal(self, points):
        center = (self.lower + self.upper) / 2
        offset = points - center
        side = np.where(offset >= 0, 1.0, -1.0)
        q = np.abs(offset) - (self.upper - self.lower) / 2
        outside = np.maximum(q, 0.0)
        outside_distance = np.linalg.norm(outside, axis=1)
        inside = outside_distance == 0
        distance = np.where(inside, q.max(axis=1), outside_distance)
        normal = _unit(outside * side)
        # Inside (or too close to tell): the outward normal of the nearest face.
        flat = ~normal.any(axis=1)
        nearest_face = np.argmax(q[flat], axis=1)
        normal[np.flatnonzero(flat), nearest_face] = side[flat, nearest_face]
        return distance, normal


@attrs.frozen(kw_only=True, eq=False)
class Polygon(Region):
    """A simple polygon in 2D (convex or not), given by its vertices in order.

    Parameters
    ----------
    vertices : array_like, shape (K, 2)
        K >= 3 vertices, clockwise or counter-clockwise, without repeating the first; the edges
        must not cross each other and the area must be non-zero.
    """

    vertices: np.ndarray = _field("Polygon.vertices")

    def __attrs_post_init__(self):
        v = self.vertices
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
            raise ValidationError(f"Polygon.vertices must have shape (K, 2) with K >= 3; got {v.shape}")
        _check_extent(v, "Polygon.vertices")
        repeated = np.flatnonzero(np.all(v == np.roll(v, -1, axis=0), axis=1))
        if len(repeated):
            k = int(repeated[0])
            raise ValidationError(
                f"Polygon.vertices {k} and {(k + 1) % len(v)} are the same point; give each vertex once, "
                "without repeating the first at the end"
            )
        if abs(self._signed_area()) <= 1e-12 * max(1.0, float(np.ptp(v)) ** 2):
            raise ValidationError("Polygon.vertices enclose no area; expected a simple polygon")
        crossing = self._crossing_edges()
        if crossing is not None:
            raise ValidationError(
                f"Polygon.vertices: edges {crossing[0]} and {crossing[1]} cross; expected a simple polygon"
            )

    @property
    def dims(self) -> int:
        return 2

    def bounds(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def centroid(self):
        a, b = self._edges()
        cross = a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]
        return ((a + b) * cross[:, None]).sum(axis=0) / (3 * cross.sum())

    def outline(self):
        return np.array(self.vertices)

    def area(self) -> float:
        """The enclosed area."""
        return abs(self._signed_area())

    def interior_point(self):
        """The point farthest inside among the vertex centroid and the centroids of the triangles
        of the fan from vertex 0 (the area centroid of a non-convex polygon may lie outside)."""
        v = self.vertices
        candidates = np.vstack([v.mean(axis=0), (v[0] + v[1:-1] + v[2:]) / 3])
        return candidates[np.argmin(self.signed_distance(candidates))]

    def _edges(self):
        return self.vertices, np.roll(self.vertices, -1, axis=0)

    def _signed_area(self) -> float:
        a, b = self._edges()
        return 0.5 * float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))

    def _crossing_edges(self):
        a, b = self._edges()
        k = len(a)

        def orient(p, q, r):
            return np.sign(
                (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
            )

        i, j = np.triu_indices(k, 1)
        adjacent = (j == i + 1) | ((i == 0) & (j == k - 1))
        i, j = i[~adjacent], j[~adjacent]
        proper = (orient(a[i], b[i], a[j]) * orient(a[i], b[i], b[j]) < 0) & (
            orient(a[j], b[j], a[i]) * orient(a[j], b[j], b[i]) < 0
        )
        hits = np.flatnonzero(proper)
        return (int(i[hits[0]]), int(j[hits[0]])) if len(hits) else None

    def _distance_and_normal(self, points):
        a, b = self._edges()
        edge = b - a  # (K, 2)
        rel = points[:, None, :] - a[None, :, :]  # (M, K, 2)
        t = np.clip(np.einsum("mkd,kd->mk", rel, edge) / np.einsum("kd,kd->k", edge, edge), 0.0, 1.0)
        closest = a[None] + t[..., None] * edge[None]
        gap = points[:, None, :] - closest
        dist2 = np.einsum("mkd,mkd->mk", gap, gap)
        nearest = np.argmin(dist2, axis=1)
        rows = np.arange(len(points))
        distance = np.sqrt(dist2[rows, nearest])
        # Even-odd rule: count edges crossed by a ray towards +x.
        y = points[:, 1:2]
        straddles = (a[None, :, 1] > y) != (b[None, :, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[None, :, 0] + (y - a[None, :, 1]) * edge[None, :, 0] / edge[None, :, 1]
        inside = (np.sum(straddles & (points[:, 0:1] < x_cross), axis=1) % 2) == 1
        sign = np.where(inside, -1.0, 1.0)
        normal = _unit(gap[rows, nearest]) * sign[:, None]
        # On the boundary the gap is zero: use the outward normal of that edge.
        ccw = 1.0 if self._signed_area() > 0 else -1.0
        edge_normals = _unit(np.stack([edge[:, 1], -edge[:, 0]], axis=1) * ccw)
        on_edge = ~normal.any(axis=1)
        normal[on_edge] = edge_normals[nearest[on_edge]]
        return distance * sign, normal


def fence(radius: float, *, posts: int | None = None, post_radius: float = 2.2) -> tuple[Ball, ...]:
    """A closed ring of round posts (2D Balls) centred `radius` from the origin: an arena that
    obstacle-avoiding behaviors (boids) turn inside, so a recording turns. `posts` defaults to as
    many as keep neighbouring posts overlapping (centres 1.6 post radii apart)."""
    radius = number(radius, "fence radius", minimum=0, strict=True, maximum=EXTENT)
    post_radius = number(post_radius, "fence post_radius", minimum=0, strict=True, maximum=EXTENT)
    if posts is None:
        posts = max(3, math.ceil(2 * math.pi * radius / (1.6 * post_radius)))
    posts = integer(posts, "fence posts", minimum=3)
    angles = np.linspace(0.0, 2 * np.pi, posts, endpoint=False)
    return tuple(Ball(center=[radius * np.cos(a), radius * np.sin(a)], radius=post_radius) for a in angles)


# -- constraints (paper 004, section 3.2) ----------------------------------------------------


def _time(value, *, field: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
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
    it within 3 sigma_com. ``solve`` meets it exactly at its aim (``flockkit.solve.com_aims``: for
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

    Natural, not scipy's default not-a-knot ends: those bent one-agent's S hardest at its ends, so
    its agent met its first keyframe at 1.46 m/s heading 47 degrees (natural: 1.17 m/s, 31
    degrees) and paid for it in every frame before. Alone on the S, as regular as least squares
    make it, the agent paid 22.05 a frame, 11.89 on the natural path; default solves (seeds 1-3,
    log g_w per agent-step, nothing else changed) went -7.25, -5.05, -5.96 -> -1.22, -1.21, -0.42
    on one-agent and -107.0, -107.2, -108.6 -> -100.4, -102.1, -108.3 on looping-3d. Through
    three, the natural cubic did no better than the quadratic (obstacle-squeeze -4.12, -13.66,
    -4.00 against -3.13, -12.63, -4.37)."""
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

    def __attrs_post_init__(self):
        if self.dims not in (2, 3):
            raise ValidationError(f"Problem.dims must be 2 or 3; got {self.dims!r}")
        if not self.duration / self.dt < MAX_FRAMES:
            raise ValidationError(
                f"Problem: duration {self.duration:g} s at dt = {self.dt:g} s is {self.duration / self.dt:.3g} "
                "frames; at most "
                f"{MAX_FRAMES} are supported (the sampler holds and simulates every frame)"
            )
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
        return round(self.duration / self.dt) + 1

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
