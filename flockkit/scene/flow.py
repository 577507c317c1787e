"""Scene constraints as arrows (paper 002, section 5.2)."""

from __future__ import annotations

from collections.abc import Mapping

import attrs
import numpy as np

from .._arrays import readonly_float
from ..errors import ValidationError
from ..validate import integer
from .features import arrow_keyframes, interpolate_arrows

__all__ = ["Arrow", "FlowField", "SelfMovement"]


def _frozen_keyframes(value, field):
    times, vectors = arrow_keyframes(value, field)
    times.setflags(write=False)
    vectors.setflags(write=False)
    return times, vectors


@attrs.frozen(kw_only=True, eq=False)
class Arrow:
    """A physical-force arrow at `position` (D,), keyframed over time: `keyframes` is
    ``[(time, vector), ...]`` (seconds, increasing; vectors of length at most 1)."""

    position: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Arrow.position"))
    keyframes: tuple = attrs.field(converter=lambda v: _frozen_keyframes(v, "Arrow.keyframes"))

    def __attrs_post_init__(self):
        if not np.any(np.linalg.norm(self.keyframes[1], axis=1) > 1e-12):
            raise ValidationError("Arrow.keyframes: every vector has zero length, so the arrow has no direction")
        if self.position.shape != self.keyframes[1].shape[1:] or not np.all(np.isfinite(self.position)):
            raise ValidationError(
                f"Arrow.position must be a finite point with as many coordinates as its vectors "
                f"({self.keyframes[1].shape[1]}); got {self.position.shape}"
            )

    @property
    def dims(self) -> int:
        return len(self.position)

    def at(self, times) -> np.ndarray:
        """The arrow (len(times), D) at `times` (seconds)."""
        return interpolate_arrows(*self.keyframes, times)


def _arrows(value) -> tuple:
    arrows = tuple(Arrow(**a) if isinstance(a, Mapping) else a for a in value)
    if not arrows or not all(isinstance(a, Arrow) for a in arrows):
        raise ValidationError("FlowField.arrows must be a non-empty sequence of flockkit.scene.Arrow (or dicts)")
    if len({a.dims for a in arrows}) != 1:
        raise ValidationError("FlowField.arrows must all have the same number of coordinates")
    return arrows


@attrs.frozen(kw_only=True, eq=False)
class FlowField:
    """Physical-force arrows placed anywhere in the scene (section 5.2). At an object's position
    the target is the arrows' weighted sum, arrow k weighing

        w_k = (1 / d_k) sum_j d_j / sum_t ((1 / d_t) sum_j d_j) = (1 / d_k) / sum_t (1 / d_t),

    d_k the distance from the object to arrow k: the paper's inverse-distance weights (the sums
    over j cancel). An object on an arrow follows that arrow alone."""

    arrows: tuple = attrs.field(converter=_arrows)

    @property
    def dims(self) -> int:
        return self.arrows[0].dims

    def weights(self, positions) -> np.ndarray:
        """(M, K): the weight of each arrow at each of `positions` (M, D); rows sum to 1."""
        positions = np.atleast_2d(np.asarray(positions, dtype=float))
        if positions.shape[1] != self.dims:
            raise ValidationError(f"FlowField: positions must have {self.dims} coordinates; got {positions.shape}")
        centers = np.stack([a.position for a in self.arrows])
        distance = np.linalg.norm(positions[:, None] - centers[None], axis=2)
        on = distance < 1e-12
        inverse = np.where(on, 0.0, 1.0 / np.where(on, 1.0, distance))
        inverse = np.where(on.any(axis=1, keepdims=True), on.astype(float), inverse)
        return inverse / inverse.sum(axis=1, keepdims=True)

    def targets(self, positions, times) -> np.ndarray:
        """(F, M, D): the target arrow at each time of `times` (F,) for each of `positions` (M, D)."""
        arrows = np.stack([a.at(times) for a in self.arrows], axis=1)  # (F, K, D)
        return np.einsum("mk,fkd->fmd", self.weights(positions), arrows)


@attrs.frozen(kw_only=True, eq=False)
class SelfMovement:
    """An arrow riding on object `object` (its index in the scene): its length and direction set
    the object's speed and heading over time; `keyframes` as for Arrow."""

    object: int = attrs.field(converter=lambda v: integer(v, "SelfMovement.object", minimum=0))
    keyframes: tuple = attrs.field(converter=lambda v: _frozen_keyframes(v, "SelfMovement.keyframes"))

    @property
    def dims(self) -> int:
        return self.keyframes[1].shape[1]

    def targets(self, times) -> np.ndarray:
        """(F, D): the object's target arrow at each time of `times`."""
        return interpolate_arrows(*self.keyframes, times)


def flow_constraints(value) -> tuple:
    """`value` as a scene's constraints: a sequence of FlowField and SelfMovement, each checked."""
    items = tuple(value or ())
    for k, item in enumerate(items):
        if not isinstance(item, FlowField | SelfMovement):
            raise ValidationError(
                f"Scene.constraints[{k}] must be flockkit.scene.FlowField or SelfMovement; got {type(item).__name__}"
            )
    return items
