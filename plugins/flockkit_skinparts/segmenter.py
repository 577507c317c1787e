"""Segmentation of a skinned mesh by its skeleton: parts are sets of joints that are neighbours
in the hierarchy and move as one rigid body over the clip.

A skin already says which vertices move together: each vertex follows its joints with their
weights. Segmenting by motion alone (``ica-kmeans``) finds what moves *at the same time*, which
on a walking animal is the gait's phase (the muzzle and the tail band swing together, diagonal
legs pair up), not its anatomy. Here:

1. Each vertex belongs to its dominant joint (largest weight); the joints that dominate some
   vertex are the starting parts.
2. Two parts are neighbours where the skeleton joins them: a joint and its parent, or two joints
   joined only through joints that dominate no vertex (an armature's root, a chain of helper
   bones; the skeleton's roots are joined through a common root) whose vertices touch (TOUCH).
   Every part is therefore a connected set of joints, and only parts that touch are joined.
3. Greedily, the pair of neighbours that together move most rigidly is merged: for the union of
   their vertices, the best rigid motion (rotation and translation, Kabsch) from the first frame
   to each frame, and the cost is the larger of the two parts' root-mean-square residuals under
   it, over vertices and frames, as a fraction of the object's size (so a small part that moves
   on its own is not outvoted by a large one). Ties go to the pair of smallest joints.
4. Merging stops at `n_parts` parts, or, with `n_parts` None, when the cheapest merge costs more
   than `threshold`. Parts whose vertices never move never join parts that move; where only such
   merges, or none, are left (a skeleton of parts that do not touch), more parts than `n_parts`
   come back.
5. Each vertex then goes to the part holding the largest share of its weight (its weights summed
   over each part's joints): a vertex shared by joints of two parts follows the one that moves it
   most.

The work is in sums: each part keeps, per frame, its point count and the sums of its positions,
their squares and their products with the first frame's, so a merge's cost takes one 3 x 3 SVD a
frame, whatever the number of vertices.
"""

from __future__ import annotations

import attrs
import numpy as np

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

# a point whose largest distance from its first position is under this fraction of the object's
# size never moves (as ica-kmeans: 0.1% of a displacement is noise of float32 files)
_STILL = 1e-6
# costs are compared after rounding to this many decimals (of the object's size), so that sums
# taken in another order of the points (a shuffled mesh) cannot change which merge comes first
_DECIMALS = 10


@attrs.frozen(kw_only=True)
class SkinParts:
    """Parameters
    ----------
    n_parts : int, optional
        Parts to end with; None: merge while a merge costs at most `threshold`.
    threshold : float
        With `n_parts` None, the largest cost of a merge (root-mean-square rigid residual, a
        fraction of the object's size; module docstring). The default, 0.02, keeps apart joints
        that turn against each other by more than about a tenth of a radian over a limb of a
        fifth of the object's size.
    """

    n_parts: int | None = validate.parameter("skin-parts", default=None, kind="integer", minimum=1, optional=True)
    threshold: float = validate.parameter("skin-parts", default=0.02, kind="number", minimum=0)

    capabilities = flockkit.Capabilities(skin=True)

    def segment(self, motion: flockkit.Motion, rng: np.random.Generator, *, skin=None) -> flockkit.Segmentation:
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"skin-parts: motion must be a flockkit.Motion; got {type(motion).__name__}")
        if not isinstance(skin, flockkit.MeshSkin):
            raise ValidationError(
                "skin-parts: needs skin= (a flockkit.MeshSkin, one row per point: what a skinned glTF mesh read by "
                f"flockkit.io.read_mesh_animation carries); got {type(skin).__name__}"
            )
        skin.check_fits(motion.n_agents, "skin-parts")
        dominant = skin.dominant()
        atoms = np.unique(dominant)  # joints that dominate some vertex: the starting parts
        if self.n_parts is not None and self.n_parts > len(atoms):
            raise ValidationError(
                f"skin-parts: n_parts={self.n_parts} is more parts than the {len(atoms)} joints that dominate some "
                "vertex of the skin"
            )
        parts = _merge(motion.positions, skin, dominant, atoms, self.n_parts, self.threshold)
        membership = np.zeros((skin.n_joints, len(parts)))
        for k, joints in enumerate(parts):
            membership[joints, k] = 1.0
        shares = skin.weight_matrix() @ membership  # (V, parts): each vertex's weight in each part
        own = membership[dominant].astype(bool)
        # a vertex goes where most of its weight is; where shares tie, to its dominant joint's part
        best = np.where(own & (shares >= shares.max(axis=1, keepdims=True) - 1e-12), 1.0, 0.0) + shares
        labels = flockkit.scene.canonical_labels(np.argmax(best, axis=1))
        return flockkit.Segmentation(labels=labels, n_parts=int(labels.max()) + 1)


def joint_adjacency(skin, points) -> list[set]:
    """For each joint of `skin` (a flockkit.MeshSkin), the joints it may be merged with: those that
    dominate some vertex and are its child or parent, or are joined to it only through joints that
    dominate none (the skeleton's roots through a common root) while their vertices touch in
    `points` (V, D), one position per vertex: the nearest two are closer than TOUCH times the
    smaller one's extent (the diagonal of its box). Empty for joints that dominate no vertex."""
    from scipy.spatial import cKDTree

    j = skin.n_joints
    dominant = skin.dominant()
    occupied = np.zeros(j + 1, dtype=bool)
    occupied[np.unique(dominant)] = True
    parent = np.where(skin.parents >= 0, skin.parents, j)  # joint j: the common root
    group = np.arange(j + 1)  # empty joints joined through empty parents: one group each

    def find(a):
        while group[a] != a:
            group[a] = group[group[a]]
            a = group[a]
        return a

    for child in range(j):
        if not occupied[child] and not occupied[parent[child]]:
            group[find(child)] = find(parent[child])
    around: dict[int, set] = {}
    adjacent = [set() for _ in range(j)]
    for child in range(j):
        up = parent[child]
        if occupied[child] and occupied[up]:
            adjacent[child].add(int(up))
            adjacent[up].add(child)
        elif occupied[child] != occupied[up]:
            inside, empty = (child, up) if occupied[child] else (up, child)
            around.setdefault(find(empty), set()).add(int(inside))
    points = np.asarray(points, dtype=np.float64)
    for members in around.values():
        members = sorted(members)
        for k, a in enumerate(members):
            for b in members[k + 1 :]:
                if b not in adjacent[a] and _touch(points[dominant == a], points[dominant == b], cKDTree):
                    adjacent[a].add(b)
                    adjacent[b].add(a)
    return adjacent


# Joints joined only through joints that dominate no vertex (an armature's root, a chain of helper
# bones) are neighbours only if their vertices come closer than this fraction of the smaller
# one's extent. On RobotExpressive the head floats 0.24 of its extent above the body (joined), and
# the feet, which hang from the armature's root as inverse kinematics targets, are 0.78 of their
# extent from the body and 1.3 from each other (apart).
TOUCH = 0.5


def _touch(a: np.ndarray, b: np.ndarray, tree) -> bool:
    extent = min(float(np.linalg.norm(np.ptp(a, axis=0))), float(np.linalg.norm(np.ptp(b, axis=0))))
    small, large = (a, b) if len(a) <= len(b) else (b, a)
    gap = float(tree(large).query(small)[0].min())
    return gap <= TOUCH * extent


class _Sums:
    """Per-frame sums of a set of points (in frames centred and scaled): count n, sums of
    positions a (T, D) and of first-frame positions b (D,), of products x_t x_0^T m (T, D, D) and
    of squares q (T,) and r."""

    def __init__(self, n, a, b, m, q, r):
        self.n, self.a, self.b, self.m, self.q, self.r = n, a, b, m, q, r

    @classmethod
    def of(cls, x: np.ndarray) -> _Sums:
        first = x[0]
        return cls(x.shape[1], x.sum(axis=1), first.sum(axis=0), np.einsum("tni,nj->tij", x, first),
                   np.einsum("tni,tni->t", x, x), float(np.sum(first * first)))  # fmt: skip

    def __add__(self, other: _Sums) -> _Sums:
        return _Sums(self.n + other.n, self.a + other.a, self.b + other.b, self.m + other.m, self.q + other.q,
                     self.r + other.r)  # fmt: skip

    def fit(self):
        """The best rigid motion x_t ~ R_t x_0 + c_t of these points (Kabsch): R (T, D, D), c (T, D)."""
        h = self.m - self.a[:, :, None] * self.b[None, None, :] / self.n
        u, _, vt = np.linalg.svd(h)
        flip = np.ones(h.shape[:2])
        flip[:, -1] = np.sign(np.linalg.det(u @ vt))
        flip[flip == 0] = 1.0
        rotation = (u * flip[:, None, :]) @ vt
        shift = (self.a - rotation @ self.b) / self.n
        return rotation, shift

    def residual(self, rotation, shift) -> float:
        """Mean squared distance of these points from R_t x_0 + c_t, over points and frames."""
        turned_b = rotation @ self.b
        sse = (self.q + self.r - 2 * np.einsum("tij,tij->t", rotation, self.m) - 2 * np.sum(shift * self.a, axis=1)
               + 2 * np.sum(shift * turned_b, axis=1) + self.n * np.sum(shift * shift, axis=1))  # fmt: skip
        return max(float(sse.mean()) / self.n, 0.0)


def rigid_residual(positions: np.ndarray) -> float:
    """The root-mean-square distance of `positions` (T, n, D) from their best rigid motion from the
    first frame (Kabsch, per frame), over points and frames: 0 for a rigid body."""
    positions = np.asarray(positions, dtype=np.float64)
    centred = positions - positions.mean(axis=1, keepdims=True)
    sums = _Sums.of(centred)
    return float(np.sqrt(sums.residual(*sums.fit())))


def _merge(positions, skin, dominant, atoms, n_parts, threshold) -> list[np.ndarray]:
    """The joints of each part (lists of joint indices), merged as the module docstring says."""
    size = float(np.linalg.norm(positions.max(axis=1) - positions.min(axis=1), axis=1).max()) or 1.0
    # centred on each frame's centroid and scaled: residuals of rigid motions do not change, and
    # the sums stay of the object's size (no cancellation of large coordinates)
    x = (positions - positions.mean(axis=1, keepdims=True)) / size
    travel = np.abs(positions - positions[:1]).max(axis=(0, 2)) / size
    parts = {int(a): [int(a)] for a in atoms}
    sums = {int(a): _Sums.of(x[:, dominant == a]) for a in atoms}
    still = {int(a): bool(travel[dominant == a].max() <= _STILL) for a in atoms}
    adjacent = joint_adjacency(skin, positions[0])
    costs = {}

    def cost(a, b):
        if still[a] != still[b]:
            return np.inf
        fit = (sums[a] + sums[b]).fit()
        return round(float(np.sqrt(max(sums[a].residual(*fit), sums[b].residual(*fit)))), _DECIMALS)

    for a in parts:
        for b in adjacent[a]:
            if a < b:
                costs[(a, b)] = cost(a, b)
    while costs and len(parts) > (n_parts or 1):
        (a, b), best = min(costs.items(), key=lambda item: (item[1], item[0]))
        if not np.isfinite(best) or (n_parts is None and best > threshold):
            break
        # b joins a (a < b): a keeps the smaller joint's name, so ties break the same way each run
        parts[a] += parts.pop(b)
        sums[a] = sums[a] + sums.pop(b)
        still[a] = still[a] and still.pop(b)
        neighbours = (adjacent[a] | adjacent[b]) - {a, b}
        adjacent[a] = neighbours
        for c in neighbours:
            adjacent[c] = (adjacent[c] - {b}) | {a}
        costs = {pair: c for pair, c in costs.items() if a not in pair and b not in pair}
        for c in neighbours:
            costs[(min(a, c), max(a, c))] = cost(a, c)
    return [np.array(sorted(joints)) for _, joints in sorted(parts.items())]
