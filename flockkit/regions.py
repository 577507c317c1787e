"""Regions of space: obstacles for behavior models, regions for walks, shapes for constraints
(``flockkit.constrained``), the ground of a scene.

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

__all__ = ["fence", "Ball", "Box", "Polygon", "Region", "EXTENT"]


def _field(name: str):
    return attrs.field(converter=functools.partial(readonly_float, field=name))


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
