"""Regions of space: obstacles for behavior models, regions for walks, shapes for constraints.

Each region offers ``contains(points)``, ``signed_distance(points)`` (negative inside) and
``surface_normal(points)`` (the outward unit normal of the nearest boundary, the gradient of the
signed distance), vectorized over points of shape (M, D).
"""

from __future__ import annotations

import functools

import attrs
import numpy as np

from ._arrays import check_finite, positive_number, readonly_float
from .errors import ValidationError

__all__ = ["Ball", "Box", "Polygon", "Region"]


def _field(name: str):
    return attrs.field(converter=functools.partial(readonly_float, field=name))


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors; vectors too short to normalize accurately (subnormal scale) become zero."""
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 1e-150)


class _Region:
    """Shared methods; subclasses define `dims` and `_distance_and_normal(points)`."""

    def _points(self, points) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64)
        if points.ndim == 0 or points.shape[-1] != self.dims:
            raise ValidationError(
                f"points for a {self.dims}D {type(self).__name__} must have shape (..., {self.dims}); got {points.shape}"
            )
        return points.reshape(-1, self.dims)

    def signed_distance(self, points) -> np.ndarray:
        """Distance from each point to the boundary, negative inside; shape points.shape[:-1]."""
        points = np.asarray(points, dtype=np.float64)
        distance, _ = self._distance_and_normal(self._points(points))
        return distance.reshape(points.shape[:-1])

    def surface_normal(self, points) -> np.ndarray:
        """Outward unit normal of the boundary nearest each point; shape points.shape."""
        points = np.asarray(points, dtype=np.float64)
        _, normal = self._distance_and_normal(self._points(points))
        return normal.reshape(points.shape)

    def contains(self, points) -> np.ndarray:
        """Whether each point lies inside or on the boundary."""
        return self.signed_distance(points) <= 0


@attrs.frozen(kw_only=True, eq=False)
class Ball(_Region):
    """A disc (2D) or sphere (3D).

    Parameters
    ----------
    center : array_like, shape (D,)
    radius : float, > 0
    """

    center: np.ndarray = _field("Ball.center")
    radius: float = attrs.field(converter=functools.partial(positive_number, field="Ball.radius"))

    def __attrs_post_init__(self):
        if self.center.shape not in ((2,), (3,)):
            raise ValidationError(f"Ball.center must have shape (2,) or (3,); got {self.center.shape}")
        check_finite(self.center, field="Ball.center")

    @property
    def dims(self) -> int:
        return self.center.shape[0]

    def _distance_and_normal(self, points):
        offset = points - self.center
        distance = np.linalg.norm(offset, axis=1)
        normal = _unit(offset)
        normal[~normal.any(axis=1), 0] = 1.0  # at the center any direction is nearest; pick +x
        return distance - self.radius, normal


@attrs.frozen(kw_only=True, eq=False)
class Box(_Region):
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
                f"Box.lower and Box.upper must both have shape (2,) or (3,); got {self.lower.shape} and {self.upper.shape}"
            )
        check_finite(self.lower, field="Box.lower")
        check_finite(self.upper, field="Box.upper")
        if not np.all(self.lower < self.upper):
            raise ValidationError(f"Box.lower must be below Box.upper in every coordinate; got {self.lower} and {self.upper}")

    @property
    def dims(self) -> int:
        return self.lower.shape[0]

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
class Polygon(_Region):
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
        check_finite(v, field="Polygon.vertices")
        if abs(self._signed_area()) <= 1e-12 * max(1.0, float(np.ptp(v)) ** 2):
            raise ValidationError("Polygon.vertices enclose no area; expected a simple polygon")
        crossing = self._crossing_edges()
        if crossing is not None:
            raise ValidationError(f"Polygon.vertices: edges {crossing[0]} and {crossing[1]} cross; expected a simple polygon")

    @property
    def dims(self) -> int:
        return 2

    def _edges(self):
        return self.vertices, np.roll(self.vertices, -1, axis=0)

    def _signed_area(self) -> float:
        a, b = self._edges()
        return 0.5 * float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))

    def _crossing_edges(self):
        a, b = self._edges()
        k = len(a)

        def orient(p, q, r):
            return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

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


Region = Ball | Box | Polygon
