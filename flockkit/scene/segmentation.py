"""Which part of an object each point belongs to (paper 002, section 4.1): a ``Segmentation`` of
a motion's points (a mesh's vertices, a flock's agents), what segmenters return."""

from __future__ import annotations

import attrs
import numpy as np

from .. import _npzfile, rigid, validate
from .._arrays import readonly_int
from ..errors import FileFormatError, ValidationError
from ..mesh import AnimatedMesh
from ..motion import Motion

__all__ = ["Segmentation", "canonical_labels", "same_partition", "merge_rigid_parts", "motion_of"]

SEGMENTATION_FORMAT_VERSION = 1


def _labels(value) -> np.ndarray:
    array = readonly_int(value, field="Segmentation.labels")
    if array.ndim != 1 or len(array) == 0:
        raise ValidationError(f"Segmentation.labels must be a non-empty 1D array; got shape {array.shape}")
    return array


@attrs.frozen(kw_only=True, eq=False)
class Segmentation:
    """The part of each point: `labels` (N,) in 0..n_parts-1, every part non-empty.

    Made as ``Segmentation(labels=[0, 0, 1], n_parts=2)``; a segmenter returns one.

    Attributes
    ----------
    labels : ndarray of int, shape (N,)
        The part of each point (agent) of the motion segmented, read-only.
    n_parts : int
        The number of parts, 1 <= n_parts <= N; each label in 0..n_parts-1 is used.
    """

    labels: np.ndarray = attrs.field(converter=_labels)
    n_parts: int = attrs.field()

    def __attrs_post_init__(self):
        if isinstance(self.n_parts, bool) or not isinstance(self.n_parts, int | np.integer) or self.n_parts < 1:
            raise ValidationError(f"Segmentation.n_parts must be a positive integer; got {self.n_parts!r}")
        if self.n_parts > len(self.labels):
            raise ValidationError(
                f"Segmentation.n_parts is {self.n_parts}, more than its {len(self.labels)} points: some part is empty"
            )
        if self.labels.min() < 0 or self.labels.max() >= self.n_parts:
            raise ValidationError(
                f"Segmentation.labels must lie in 0..{self.n_parts - 1}; got {self.labels.min()}..{self.labels.max()}"
            )
        empty = np.flatnonzero(np.bincount(self.labels, minlength=self.n_parts) == 0)
        if len(empty):
            raise ValidationError(f"Segmentation: part {int(empty[0])} of {self.n_parts} has no point")

    @property
    def n_points(self) -> int:
        """N, the number of points labelled."""
        return len(self.labels)

    def parts(self) -> list[np.ndarray]:
        """Each part's point indices, increasing."""
        order = np.argsort(self.labels, kind="stable")
        return np.split(order, np.cumsum(np.bincount(self.labels, minlength=self.n_parts))[:-1])

    def check_fits(self, motion: Motion, what: str = "the motion") -> None:
        """ValidationError unless there is one label per point of `motion`."""
        if self.n_points != motion.n_agents:
            raise ValidationError(f"the segmentation labels {self.n_points} points but {what} has {motion.n_agents}")

    def __eq__(self, other):
        if not isinstance(other, Segmentation):
            return NotImplemented
        return self.n_parts == other.n_parts and np.array_equal(self.labels, other.labels)

    __hash__ = None

    def save(self, path) -> None:
        """Write to one .npz with JSON metadata (atomic)."""
        _npzfile.write(path, kind="segmentation", version=SEGMENTATION_FORMAT_VERSION, arrays={"labels": self.labels},
                       metadata={"n_parts": self.n_parts})  # fmt: skip

    @classmethod
    def load(cls, path) -> Segmentation:
        arrays, header = _npzfile.read(path, kind="segmentation", versions=(SEGMENTATION_FORMAT_VERSION,))
        try:
            return cls(labels=arrays["labels"], n_parts=header["n_parts"])
        except (KeyError, ValidationError) as exc:
            raise FileFormatError(f"{path}: invalid segmentation: {type(exc).__name__}: {exc}") from None


def motion_of(source, what: str = "source") -> Motion:
    """The Motion of a Motion or an AnimatedMesh."""
    if isinstance(source, AnimatedMesh):
        return source.motion
    if isinstance(source, Motion):
        return source
    raise ValidationError(f"{what} must be a flockkit.Motion or flockkit.AnimatedMesh; got {type(source).__name__}")


def canonical_labels(labels) -> np.ndarray:
    """Part labels renamed 0, 1, ... in order of each part's first point: equal partitions give
    equal arrays, whatever the names a segmenter chose."""
    _, first, inverse = np.unique(np.asarray(labels), return_index=True, return_inverse=True)
    return np.argsort(np.argsort(first))[inverse]


def same_partition(a, b) -> bool:
    """Whether two labelings split the points the same way, whatever the part names."""
    return np.array_equal(canonical_labels(a), canonical_labels(b))


def _moves_rigidly(points: np.ndarray, tolerance: float) -> bool:
    """Whether (T, n, D) points move as one rigid body: every frame a rotation and translation of
    the first, to `tolerance` of their extent (Kabsch, in chunks of frames)."""
    centered = points - points.mean(axis=1, keepdims=True)
    extent = float(np.abs(centered).max(initial=0.0))
    if extent == 0.0:
        return True
    frames, n, dims = centered.shape
    chunk = max(1, 2**22 // (n * dims * dims))  # kabsch forms (frames, n, D, D) products
    for start in range(0, frames, chunk):
        part = centered[start : start + chunk]
        placed = np.einsum("tij,tnj->tni", rigid.kabsch(centered[:1], part), part)
        if float(np.abs(placed - centered[0]).max()) > tolerance * extent:
            return False
    return True


def _rigid_pair(positions, bodies, tolerance):
    """The first (i, j), i < j, of bodies that together move rigidly, or None."""
    for i in range(len(bodies)):
        for j in range(i + 1, len(bodies)):
            if _moves_rigidly(positions[:, np.concatenate([bodies[i], bodies[j]])], tolerance):
                return i, j
    return None


def merge_rigid_parts(motion, labels, *, tolerance: float = 1e-5) -> np.ndarray:
    """`labels` (one per point of `motion`, a Motion or AnimatedMesh) with every set of parts that
    together move as one rigid body made one part, relabelled 0, 1, ... (canonical_labels).

    A body that turns as it travels moves each point differently (those far from the turning
    centre more), so segmenters that compare points' motions cut it, though nothing in it moves
    independently. Parts are rigid together when every frame is a rotation and translation of
    the first to `tolerance` of their extent (largest coordinate from their centre). Parts that
    never move are rigid with each other but with no moving part. A part that deforms joins
    nothing, so on deforming objects this costs one test per part."""
    positions = motion_of(motion, "motion").positions
    labels = np.asarray(labels)
    if labels.shape != (positions.shape[1],):
        raise ValidationError(f"labels must have one entry per point ({positions.shape[1]}); got shape {labels.shape}")
    tolerance = validate.number(tolerance, "tolerance", minimum=0)
    parts = [np.flatnonzero(labels == k) for k in np.unique(labels)]
    bodies = [p for p in parts if _moves_rigidly(positions[:, p], tolerance)]
    while (pair := _rigid_pair(positions, bodies, tolerance)) is not None:
        i, j = pair
        bodies[i] = np.concatenate([bodies[i], bodies[j]])
        del bodies[j]
    out = labels.copy()
    for body in bodies:
        out[body] = labels[body[0]]
    return canonical_labels(out)
