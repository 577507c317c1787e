"""Where each object of a scene stands (paper 002, section 5.1): its position on the ground, its
heading about +z and its scale, and the geometry of turned footprints."""

from __future__ import annotations

import math

import attrs
import numpy as np

from .. import rigid
from .._arrays import readonly_float
from ..motion import DEFAULT_UP

# Tries per object when placing before the region is declared too small.
PLACEMENT_TRIES = 200


@attrs.frozen(kw_only=True, eq=False)
class Placement:
    """Where each object of a scene stands: `positions` (M, 2) on the ground, `headings` (M,)
    radians about +z, `scales` (M,), `templates` (M,) the template each duplicates."""

    positions: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.positions"))
    headings: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.headings"))
    scales: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.scales"))
    templates: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.int64))

    @property
    def n_objects(self) -> int:
        return len(self.positions)

    def __eq__(self, other):
        if not isinstance(other, Placement):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, f), getattr(other, f))
            for f in ("positions", "headings", "scales", "templates")
        )

    __hash__ = None


def heading_turn(heading: float, dims: int) -> np.ndarray:
    """The rotation by `heading` about the up axis (in 2D, in the plane)."""
    return rigid.rotation(heading) if dims == 2 else rigid.rotation(heading, DEFAULT_UP)


def turned_half(half: np.ndarray, heading: float) -> np.ndarray:
    """Half extents of the axis-aligned box around a box of half extents `half` turned by `heading`."""
    c, s = abs(math.cos(heading)), abs(math.sin(heading))
    return np.array([c * half[0] + s * half[1], s * half[0] + c * half[1]])
