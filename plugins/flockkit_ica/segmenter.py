"""Segmentation by independent component analysis (paper 002, section 4.1).

1. The velocity-energy matrix: for point s and frame t, the summed squared displacement over a
   window of 2n frames, sum_{k=-n}^{n-1} |x_s(t+k+1) - x_s(t+k)|^2 (`window` = n, default 1).
2. Points that never move (their largest energy under 1e-6 of the largest point's) form a part of
   their own: ICA would give them arbitrary rows.
3. FastICA of the energies of the moving points, frames as samples and points as features, so
   that each point has a row of the mixing matrix: how much of each independent component its
   motion carries.
4. k-means on those rows, scaled to unit length (which components a point follows, not how far it
   moves; the amount of motion is what the energy already separates from static points).
5. The points are taken in a canonical order (their trajectories sorted lexicographically), so
   that shuffling the input's points shuffles the labels with them: FastICA's and k-means'
   seeded starts pick points by index, and would otherwise find other parts for another order.
6. With `n_parts` None, parts whose points together move as one rigid body (every frame a
   rotation and translation of the first, to 1e-5 of their extent) are merged: the energies of
   a body that turns as it travels differ from point to point, and k-means cuts it, although
   nothing in it moves independently.

The paper sets the number of parts by hand and names choosing it as future work. With `n_parts`
None it is chosen: `n_components` (if None) is the number of principal components that explain
99% of the energy's variance (at most `max_components`); with one component the moving points are
one part; otherwise k runs over 2..n_components + 2 and the k with the largest silhouette score of
the rows (on a sample of at most 2 000 points) wins (the smallest k within 0.001 of it). On
MorphStressTest this finds the eight morph targets exactly (plus the unmoved vertices: 9 parts).
"""

from __future__ import annotations

import warnings

import attrs
import numpy as np

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

# below this fraction of the largest point's largest energy, a point never moves (our choice:
# 1e-6 of the energy is 0.1% of the displacement)
_STILL = 1e-6
_EXPLAINED = 0.99
# parts that move together as one rigid body within this fraction of their extent are one part
_RIGID = 1e-5


def velocity_energy(positions: np.ndarray, window: int) -> np.ndarray:
    """(T - 2 window, N): the summed squared displacement of each point over 2 window frames."""
    steps = np.sum(np.diff(positions, axis=0) ** 2, axis=2)  # (T - 1, N)
    frames = len(steps) - 2 * window + 1
    if frames < 2:
        raise ValidationError(
            f"ica-kmeans: a motion of {len(positions)} frames is too short for window={window}; it needs at least "
            f"{2 * window + 2}"
        )
    return sum(steps[k : k + frames] for k in range(2 * window))


@attrs.frozen(kw_only=True)
class IcaKmeans:
    """Parameters
    ----------
    n_parts : int, optional
        Parts, the unmoving points' part included; None: chosen (module docstring).
    n_components : int, optional
        Independent components; None: those explaining 99% of the energy's variance.
    window : int
        n of the energy window (2n frames).
    max_components : int
        Upper bound on the chosen number of components.
    """

    n_parts: int | None = validate.parameter("ica-kmeans", default=None, kind="integer", minimum=1, optional=True)
    n_components: int | None = validate.parameter("ica-kmeans", default=None, kind="integer", minimum=1, optional=True)
    window: int = validate.parameter("ica-kmeans", default=1, kind="integer", minimum=1)
    max_components: int = validate.parameter("ica-kmeans", default=20, kind="integer", minimum=1)

    def segment(self, motion: flockkit.Motion, rng: np.random.Generator) -> flockkit.Segmentation:
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"ica-kmeans: motion must be a flockkit.Motion; got {type(motion).__name__}")
        n = motion.n_agents
        if self.n_parts is not None and self.n_parts > n:
            raise ValidationError(f"ica-kmeans: n_parts={self.n_parts} is more parts than the motion's {n} points")
        energy = velocity_energy(motion.positions, self.window)
        peak = energy.max(axis=0)
        moving = peak > _STILL * max(peak.max(), 1e-300)
        labels = np.zeros(n, dtype=np.int64)
        still = int(not moving.all())  # the unmoving points are part 0
        wanted = None if self.n_parts is None else self.n_parts - still
        if moving.sum() == 0 or wanted == 0:
            return flockkit.Segmentation(labels=labels, n_parts=1)
        seed = int(rng.integers(2**31 - 1))
        moving_points = np.flatnonzero(moving)
        order = moving_points[_canonical_order(motion.positions[:, moving_points])]
        labels[order] = self._moving_parts(energy[:, order], wanted, seed) + still
        if wanted is None:
            labels = flockkit.scene.merge_rigid_parts(motion, labels, tolerance=_RIGID)
        return flockkit.Segmentation(labels=flockkit.scene.canonical_labels(labels), n_parts=int(labels.max()) + 1)

    def _moving_parts(self, energy: np.ndarray, wanted: int | None, seed: int) -> np.ndarray:
        """Labels 0.. of the moving points (columns of `energy`)."""
        points = energy.shape[1]
        if wanted is not None and wanted > points:
            raise ValidationError(f"ica-kmeans: {wanted} moving parts asked for but only {points} points move")
        if wanted is None:
            # points whose energies are the same series move together: one row each for ICA (a
            # rigid group translating at constant speed gives the same constant series, on
            # which ICA's rows are noise)
            scaled = energy / max(float(energy.max()), 1e-300)
            _, first, same = np.unique(np.round(scaled, 9), axis=1, return_index=True, return_inverse=True)
            if len(first) < points:
                return self._moving_parts(energy[:, first], None, seed)[same.ravel()]
        components = self.n_components or _explaining(energy, self.max_components)
        components = min(components, points, energy.shape[0])
        if wanted == 1 or points == 1 or (wanted is None and components == 1):
            return np.zeros(points, dtype=np.int64)
        rows = _mixing_rows(energy, components, seed)
        if wanted is not None:
            return _kmeans(rows, wanted, seed)
        from sklearn.metrics import silhouette_score

        best, chosen = -np.inf, None
        for k in range(2, min(components + 2, points - 1) + 1):
            labels = _kmeans(rows, k, seed)
            if len(np.unique(labels)) < 2:
                continue
            # on a sample of at most 2 000 points: the score is quadratic in the points
            score = silhouette_score(rows, labels, sample_size=min(points, 2000), random_state=seed)
            if score > best + 1e-3:
                best, chosen = score, labels
        return chosen if chosen is not None else np.zeros(points, dtype=np.int64)


def _canonical_order(positions: np.ndarray) -> np.ndarray:
    """The points of `positions` (T, N, D) sorted by their whole trajectories, lexicographically
    (points with the same trajectory keep their order: nothing tells them apart)."""
    trajectories = np.ascontiguousarray(positions.transpose(1, 0, 2).reshape(positions.shape[1], -1))
    _, inverse = np.unique(trajectories, axis=0, return_inverse=True)
    return np.argsort(inverse.ravel(), kind="stable")


def _explaining(energy: np.ndarray, most: int) -> int:
    """Principal components explaining _EXPLAINED of the energy's variance, at most `most`."""
    centered = energy - energy.mean(axis=0)
    singular = np.linalg.svd(centered, compute_uv=False)
    if np.sum(singular**2) <= 1e-18 * max(float(np.sum(energy**2)), 1e-300):
        return 1  # every series constant: nothing varies for components to explain
    share = np.cumsum(singular**2) / max(np.sum(singular**2), 1e-300)
    return int(min(np.searchsorted(share, _EXPLAINED) + 1, most))


def _mixing_rows(energy: np.ndarray, components: int, seed: int) -> np.ndarray:
    """The rows of FastICA's mixing matrix (one per point), scaled to unit length."""
    from sklearn.decomposition import FastICA

    # scaled so that tolerances mean the same whatever the units
    scaled = energy / max(float(np.abs(energy).max()), 1e-300)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a slow convergence still gives usable rows
        ica = FastICA(n_components=components, random_state=seed, max_iter=2000, whiten="unit-variance")
        ica.fit(scaled)
    rows = ica.mixing_
    return rows / np.maximum(np.linalg.norm(rows, axis=1, keepdims=True), 1e-300)


def _kmeans(rows: np.ndarray, k: int, seed: int) -> np.ndarray:
    from sklearn.cluster import KMeans

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # rigid groups give identical rows: fewer distinct clusters than k
        return KMeans(n_clusters=k, n_init=10, random_state=seed).fit_predict(rows).astype(np.int64)
