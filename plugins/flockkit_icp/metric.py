"""The configuration metric of paper 000 section 4.2: ICP alternating with Kuhn-Munkres matching.

E(a, b) = min over rotations R, translations t and one-to-one assignments M of
          (1/N) sum_i |a_i - (R b_M(i) + t)|^2   + velocity_weight * (1/N) sum_i |v_i - R w_M(i)|^2
(velocity_weight = 0 is the paper's E; the default weighs velocities too, see IcpHungarian).

Every agent is matched, so the best translation always maps centroid onto centroid; the search
works on centered positions and alternates the optimal assignment for the current rotation
(`scipy.optimize.linear_sum_assignment`) with the optimal rotation for the current assignment
(Kabsch, proper rotations only) until the distance stops decreasing. Because that only finds a
local minimum, it starts from several rotations and keeps the best: the configuration-space
alignment (section 4.1), the same turned by pi, and the principal-axes alignments. The search runs
on many pairs at once (`pairwise`); `compare` is the one-pair case of the same code, so both give
bit-identical distances.

Bounds. With V the mean velocity and d_i = v_i - V the deviations, the velocity term splits
exactly into w |V_a - R V_b|^2 + (w/N) sum_i |d_i - R d'_M(i)|^2 (the deviations sum to zero).
`lower_bound` drops the rotation: sorted distances to the center of mass, sorted deviation
speeds and the difference of mean speeds. `pairs_within` (2D) keeps it: over an interval of
angles every entry of the assignment cost has a closed-form minimum, so the mean of the row
minima plus the interval's minimum of the mean-velocity term bounds E for every rotation in the
interval (a quick test), and the optimal assignment of the entries' minima bounds tighter.
Intervals whose bound exceeds the threshold are dropped and the others halved (branch and bound)
seven times; a pair is listed when an interval survives, or as soon as the assignment found for
one, at its own best rotation, reaches a distance within the threshold.
"""

from __future__ import annotations

import math

import attrs
import numpy as np
from scipy.optimize import linear_sum_assignment

import flockkit
from flockkit.errors import ValidationError

_CHUNK = 256  # pairs searched together: bounds the (pairs x starts x N x N) cost array
_BOUND_CHUNK = 2048  # pairs bounded together
_BLOCK = 1  # pairs_within certifies blocks of (2 * _BLOCK + 1)^2 neighboring pairs at once


def _positive(name):
    def check(instance, attribute, value):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ValidationError(f"icp-hungarian parameter {name} must be a finite number > 0; got {value!r}")

    return check


def _non_negative_number(instance, attribute, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise ValidationError(f"icp-hungarian parameter velocity_weight must be a finite number >= 0; got {value!r}")


def _iterations(instance, attribute, value):
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValidationError(f"icp-hungarian parameter max_iterations must be an integer >= 1; got {value!r}")


@attrs.frozen(kw_only=True)
class IcpHungarian:
    """Rigid- and permutation-invariant distance between configurations.

    Parameters
    ----------
    velocity_weight : float
        Weight, in seconds squared, of the mean squared velocity residual (velocities are rotated
        with the positions, not translated). The default 0.25 s^2 counts a velocity mismatch like
        the position error it makes within half a second: transitions between groups that move
        differently show as jerks in synthesis (measured: the largest synthesized step falls from
        2.1x to 1.2x the source's largest on a boids recording). 0 gives E of the paper exactly.
    max_iterations : int
        Alternations per start at most.
    tolerance : float
        Stop when an alternation lowers the distance by less than this fraction.
    up : sequence of 3 floats
        World up for the 3D configuration-space start.
    """

    velocity_weight: float = attrs.field(default=0.25, validator=_non_negative_number)
    max_iterations: int = attrs.field(default=50, validator=_iterations)
    tolerance: float = attrs.field(default=1e-10, validator=_positive("tolerance"))
    up: tuple = attrs.field(default=flockkit.DEFAULT_UP, converter=tuple)

    def compare(self, a: flockkit.Configuration, b: flockkit.Configuration) -> flockkit.Alignment:
        """The alignment of `b` onto `a` with the smallest distance found (see the module docstring)."""
        self._check_pair(a, b)
        prepared = _Prepared([a, b], self.up)
        distance, assignment, rotation = self._search(prepared, np.array([0]), np.array([1]))
        rotation = rotation[0]
        return flockkit.Alignment(
            distance=max(float(distance[0]), 0.0), assignment=assignment[0], rotation=rotation,
            translation=prepared.com[0] - rotation @ prepared.com[1],
        )

    def pairwise(self, configurations, pairs=None) -> np.ndarray:
        """Distances for many pairs at once, shape (P,): ``compare(c[i], c[j]).distance`` for each
        row (i, j) of `pairs` (shape (P, 2)). Without `pairs`, every i < j in row-major order, the
        condensed form of ``scipy.spatial.distance.pdist`` (``squareform`` makes the matrix)."""
        configurations = self._check_many(configurations)
        k = len(configurations)
        pairs = np.column_stack(np.triu_indices(k, 1)) if pairs is None else _checked_pairs(pairs, k)
        prepared = _Prepared(configurations, self.up)
        distances = np.empty(len(pairs))
        for start in range(0, len(pairs), _CHUNK):
            chunk = pairs[start : start + _CHUNK]
            distances[start : start + _CHUNK] = self._search(prepared, chunk[:, 0], chunk[:, 1])[0]
        return np.maximum(distances, 0.0)

    def lower_bound(self, a: flockkit.Configuration, b: flockkit.Configuration) -> float:
        """A proven lower bound on ``compare(a, b).distance``, in O(N log N).

        Rotations keep each agent's distance to the center of mass, and centers of mass always
        correspond, so |a_i - R b_j - t| >= | |a_i - ca| - |b_j - cb| |; the best one-to-one
        matching of those radii (rearrangement inequality) is the sorted one. The velocity term
        is bounded the same way with the deviation speeds, plus the mean speeds' difference.
        """
        self._check_pair(a, b)
        prepared = _Prepared([a, b], self.up)
        return float(self._rotation_free_bound(prepared, np.array([0]), np.array([1]))[0])

    def pairs_within(self, configurations, threshold: float, *, rows=None) -> np.ndarray:
        """Every pair (i, j), i < j, whose distance may be at most `threshold`, shape (P, 2), sorted:
        pairs left out are proven farther apart (see the module docstring). `rows` = (start, stop)
        keeps the pairs with start <= i < stop, so that workers can share the job.

        Neighboring configurations of a recording are close, which saves most of the work: the
        metric (its exact minimum) obeys the triangle inequality, so if the bound between
        configurations p and q exceeds (sqrt(threshold) + r_p + r_q)^2, where r_p bounds the
        distance from p to each configuration within `_BLOCK` places of it (the identity
        assignment, best rotation), no pair of those two blocks can be within the threshold."""
        configurations = self._check_many(configurations)
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not threshold >= 0:
            raise ValidationError(f"icp-hungarian.pairs_within: threshold must be a number >= 0; got {threshold!r}")
        k = len(configurations)
        first, stop = (0, k) if rows is None else (int(rows[0]), int(rows[1]))
        if not 0 <= first <= stop <= k:
            raise ValidationError(f"icp-hungarian.pairs_within: rows must be (start, stop) with 0 <= start <= stop <= {k}; got {rows!r}")
        prepared = _Prepared(configurations, self.up)
        limit = float(threshold)
        if prepared.dims == 3:
            i, j = np.triu_indices(k, 1)
            inside = (i >= first) & (i < stop)
            return self._filter(prepared, i[inside], j[inside], limit)
        size = 2 * _BLOCK + 1
        starts = np.arange(0, k, size)  # blocks of `size` neighbors, the last one maybe shorter
        centres = np.minimum(starts + _BLOCK, k - 1)
        reach = self._block_reach(prepared, starts, centres, size)
        p, q = np.triu_indices(len(starts))
        mine = (starts[p] + size > first) & (starts[p] < stop)
        p, q = p[mine], q[mine]
        widened = (math.sqrt(limit) + reach[p] + reach[q]) ** 2
        found = []
        for bp, bq in self._filter(prepared, centres[p], centres[q], widened, blocks=(p, q)):
            # these two blocks were not ruled out together: look at their pairs one by one
            row_range = np.arange(max(first, starts[bp]), min(stop, starts[bp] + size))
            i, j = (x.ravel() for x in np.meshgrid(row_range, np.arange(starts[bq], min(k, starts[bq] + size)), indexing="ij"))
            found.append((i[i < j], j[i < j]))
        if not found:
            return np.zeros((0, 2), dtype=int)
        i, j = np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])
        listed = self._filter(prepared, i, j, np.full(len(i), limit))
        return listed[np.lexsort((listed[:, 1], listed[:, 0]))]

    def _filter(self, prepared, ia, ib, limit, blocks=None) -> np.ndarray:
        """Rows of (ia, ib) (or of `blocks`) whose pair may be within `limit` (one per pair)."""
        ia, ib = np.asarray(ia), np.asarray(ib)
        # rounding must never drop a pair at the limit: allow for it relative to the pair's size
        limit = limit * (1 + 1e-9) + 1e-9 * (prepared.scale[ia] + prepared.scale[ib] + self.velocity_weight * (prepared.speed_scale[ia] + prepared.speed_scale[ib]))
        keep = np.zeros(len(ia), dtype=bool)
        for s in range(0, len(ia), _BOUND_CHUNK):
            part = slice(s, s + _BOUND_CHUNK)
            floor = self._rotation_free_bound(prepared, ia[part], ib[part], mean_velocity=False)
            mean_part = self.velocity_weight * (prepared.mean_speed[ia[part]] - prepared.mean_speed[ib[part]]) ** 2
            kept = np.flatnonzero(floor + mean_part <= limit[part])
            if prepared.dims == 2 and len(kept):
                rounding = 1e-6 * prepared.n_agents * (prepared.scale + self.velocity_weight * prepared.speed_scale)
                slack = limit[part][kept] + rounding[ia[part][kept]] + rounding[ib[part][kept]]
                kept = kept[_branch_and_bound(prepared, ia[part][kept], ib[part][kept], self.velocity_weight, slack, floor[kept])]
            keep[s + kept] = True
        labels = (ia, ib) if blocks is None else blocks
        return np.column_stack([labels[0][keep], labels[1][keep]]).astype(int)

    def _block_reach(self, prepared, starts, centres, size) -> np.ndarray:
        """For each block, an upper bound on the distance from its centre to each of its members."""
        k, reach = len(prepared.centered), np.zeros(len(centres))
        for offset in range(size):
            members = np.minimum(starts + offset, k - 1)
            reach = np.maximum(reach, self._identity_distance(prepared, centres, members))
        return reach

    def _identity_distance(self, prepared, ia, ib) -> np.ndarray:
        """sqrt of the distance with the identity assignment and its best rotation: >= the metric's."""
        w = self.velocity_weight
        source = np.concatenate([prepared.centered[ib], math.sqrt(w) * prepared.velocities[ib]], axis=1)
        target = np.concatenate([prepared.centered[ia], math.sqrt(w) * prepared.velocities[ia]], axis=1)
        rotation = _kabsch(target, source)
        return np.sqrt(((target - _rotate(source, rotation)) ** 2).sum(axis=(1, 2)) / prepared.n_agents)

    # -- internals -------------------------------------------------------------------------

    def _check_pair(self, a, b):
        for name, value in (("a", a), ("b", b)):
            if not isinstance(value, flockkit.Configuration):
                raise ValidationError(f"icp-hungarian: {name} must be a flockkit.Configuration; got {type(value).__name__}")
        if a.positions.shape != b.positions.shape:
            raise ValidationError(
                f"icp-hungarian compares configurations of the same size; got {a.n_agents} agents in {a.dims}D "
                f"and {b.n_agents} in {b.dims}D"
            )

    def _check_many(self, configurations) -> list:
        configurations = list(configurations)
        for index, config in enumerate(configurations):
            if not isinstance(config, flockkit.Configuration):
                raise ValidationError(f"icp-hungarian: configurations[{index}] must be a flockkit.Configuration; got {type(config).__name__}")
            self._check_pair(configurations[0], config)
        return configurations

    def _rotation_free_bound(self, prepared, ia, ib, mean_velocity=True) -> np.ndarray:
        """lower_bound for the pairs (ia[p], ib[p]) (without the mean velocities' part if asked)."""
        n, w = prepared.n_agents, self.velocity_weight
        bound = ((prepared.sorted_radii[ia] - prepared.sorted_radii[ib]) ** 2).sum(axis=1) / n
        if w:
            bound += w * ((prepared.sorted_deviation_speeds[ia] - prepared.sorted_deviation_speeds[ib]) ** 2).sum(axis=1) / n
            if mean_velocity:
                bound += w * (prepared.mean_speed[ia] - prepared.mean_speed[ib]) ** 2
        return bound

    def _search(self, prepared, ia, ib):
        """ICP from every start for pairs (ia[p], ib[p]): (distances, assignments, rotations) of the best."""
        starts = prepared.starts(ia, ib)  # (P, S, D, D)
        p, s, d = starts.shape[0], starts.shape[1], prepared.dims
        pick = lambda array, index: np.repeat(array[index], s, axis=0)  # noqa: E731
        distance, assignment, rotation = self._descend(
            pick(prepared.centered, ia), pick(prepared.centered, ib),
            pick(prepared.velocities, ia), pick(prepared.velocities, ib), starts.reshape(p * s, d, d),
        )
        best = np.argmin(distance.reshape(p, s), axis=1)  # the first start wins ties
        flat = np.arange(p) * s + best
        return distance[flat], assignment[flat], rotation[flat]

    def _descend(self, pa, pb, va, vb, rotation):
        """Alternate assignment and rotation from each start until its distance stops falling."""
        m, n, _ = pa.shape
        w = self.velocity_weight
        best = np.full(m, np.inf)
        best_assignment = np.tile(np.arange(n), (m, 1))
        best_rotation = rotation.copy()
        rotation = rotation.copy()
        active = np.arange(m)
        root = math.sqrt(w)
        # positions and root(w) * velocities side by side: one cost matrix holds both terms
        left = np.concatenate([pa, root * va], axis=2) if w else pa
        for _ in range(self.max_iterations):
            right = _rotate(pb[active], rotation[active])
            if w:
                right = np.concatenate([right, root * _rotate(vb[active], rotation[active])], axis=2)
            cost = _pair_costs(left[active], right)
            assignment = np.array([linear_sum_assignment(c)[1] for c in cost])
            distance = np.take_along_axis(cost, assignment[:, :, None], axis=2)[:, :, 0].sum(axis=1) / n
            previous = best[active]
            improved = distance < previous
            better = active[improved]
            # an unchanged assignment gives back the same rotation: nothing more to gain
            moved = np.any(assignment != best_assignment[active], axis=1) | ~np.isfinite(previous)
            best[better], best_assignment[better], best_rotation[better] = distance[improved], assignment[improved], rotation[better]
            going = improved & moved & (distance < previous * (1 - self.tolerance))
            active, assignment = active[going], assignment[going]
            if not len(active):
                break
            rotation[active] = _kabsch(pa[active], _gather(pb[active], assignment), va[active], _gather(vb[active], assignment), w)
        return best, best_assignment, best_rotation


class _Prepared:
    """Per-configuration arrays for a list of same-sized configurations."""

    def __init__(self, configurations, up):
        positions = np.stack([c.positions for c in configurations])
        self.n_agents, self.dims = positions.shape[1], positions.shape[2]
        self.com = positions.mean(axis=1)
        self.centered = positions - self.com[:, None, :]
        self.velocities = np.stack([c.velocities for c in configurations])
        self.frames = flockkit.heading_axes(self.velocities, up=up)
        self.principal = _principal_axes(self.centered)
        mean_velocity = self.velocities.mean(axis=1)
        self.deviations = self.velocities - mean_velocity[:, None, :]
        self.mean_velocity = mean_velocity
        self.mean_speed = np.linalg.norm(mean_velocity, axis=1)
        self.sorted_radii = np.sort(np.linalg.norm(self.centered, axis=2), axis=1)
        self.sorted_deviation_speeds = np.sort(np.linalg.norm(self.deviations, axis=2), axis=1)
        self.scale = (self.centered**2).sum(axis=(1, 2)) / self.n_agents  # mean squared radius
        self.speed_scale = (self.velocities**2).sum(axis=(1, 2)) / self.n_agents

    def starts(self, ia, ib) -> np.ndarray:
        """Start rotations (P, S, D, D): configuration frames then principal axes, for each half turn."""
        starts = []
        for turn in _half_turns(self.dims):
            for axes in (self.frames, self.principal):
                starts.append(np.transpose(axes[ia], (0, 2, 1)) @ turn @ axes[ib])
        return np.stack(starts, axis=1)


def _principal_axes(points: np.ndarray) -> np.ndarray:
    """Rows: principal directions of centered point sets (K, N, D), largest spread first, proper."""
    _, vectors = np.linalg.eigh(np.transpose(points, (0, 2, 1)) @ points)
    axes = np.transpose(vectors[:, :, ::-1], (0, 2, 1)).copy()
    axes[np.linalg.det(axes) < 0, -1] *= -1
    return axes


def _half_turns(d: int) -> list[np.ndarray]:
    """The identity and the rotations by pi about each coordinate axis (in 2D: about the origin)."""
    if d == 2:
        return [np.eye(2), -np.eye(2)]
    return [np.eye(3)] + [np.diag(np.where(np.arange(3) == k, 1.0, -1.0)) for k in range(3)]


def _rotate(points, rotation):
    """points @ rotation.T for stacks (M, N, D) and (M, D, D), elementwise, so a pair's result does
    not depend on the batch it is in."""
    d = points.shape[2]
    return np.stack([sum(points[:, :, k] * rotation[:, e, k, None] for k in range(d)) for e in range(d)], axis=2)


def _pair_costs(x, y):
    """Squared distances (M, N, N) between the rows of x (M, N, D) and y (M, N, D), as
    |x|^2 + |y|^2 - 2 x.y: ten times faster than differences. The batched product multiplies each
    pair's matrices on their own, so a pair's result does not depend on the batch it is in."""
    cost = x @ np.transpose(y, (0, 2, 1))
    cost *= -2
    cost += (x * x).sum(axis=2)[:, :, None]
    cost += (y * y).sum(axis=2)[:, None, :]
    return cost


def _gather(points, assignment):
    return np.take_along_axis(points, assignment[:, :, None], axis=1)


def _kabsch(target, source, target_velocities=None, source_velocities=None, w=0.0):
    """Proper rotations R (M, D, D) minimizing sum |target - R source|^2 (+ w for velocities)."""
    cross = (source[:, :, :, None] * target[:, :, None, :]).sum(axis=1)  # sum_i s_i t_i^T
    if w:
        cross = cross + w * (source_velocities[:, :, :, None] * target_velocities[:, :, None, :]).sum(axis=1)
    if target.shape[2] == 2:
        angle = np.arctan2(cross[:, 0, 1] - cross[:, 1, 0], cross[:, 0, 0] + cross[:, 1, 1])
        c, s = np.cos(angle), np.sin(angle)
        return np.stack([np.stack([c, -s], axis=1), np.stack([s, c], axis=1)], axis=1)
    u, _, vt = np.linalg.svd(cross)
    v = np.transpose(vt, (0, 2, 1))
    signs = np.ones((len(cross), 3))
    flip = np.linalg.det(v @ np.transpose(u, (0, 2, 1))) < 0
    signs[flip, -1] = -1.0
    return (v * signs[:, None, :]) @ np.transpose(u, (0, 2, 1))


def _branch_and_bound(prepared, ia, ib, w, limit, floor, levels=7) -> np.ndarray:
    """Mask over pairs (ia, ib) (2D): True where some rotation interval keeps the bound <= limit
    (one limit per pair). `floor` bounds the position and deviation part for every rotation."""
    n = prepared.n_agents
    root = math.sqrt(w)
    # a . R(theta) b = p cos(theta) + q sin(theta), for positions plus root(w) * deviations
    stacked = np.concatenate([prepared.centered, root * prepared.deviations], axis=2)
    left, right = stacked[ia], stacked[ib]  # (P, N, 4): x, y, dx, dy
    turned = right[:, :, [1, 0, 3, 2]] * np.array([-1.0, 1.0, -1.0, 1.0])  # (-y, x, -dy, dx)
    p_all = left @ np.transpose(right, (0, 2, 1))
    q_all = left @ np.transpose(turned, (0, 2, 1))  # ay bx - ax by (+ deviations)
    # each entry |a_i - R b_j|^2 (+ deviations) = a - h cos(theta - phase); float32 halves the
    # memory traffic, and the limit allows for its rounding (see _filter)
    left_squares, right_squares = (left**2).sum(axis=2), (right**2).sum(axis=2)
    a_all = (left_squares[:, :, None] + right_squares[:, None, :]).astype(np.float32)
    h_all = (2 * np.sqrt(p_all * p_all + q_all * q_all)).astype(np.float32)
    p2_all, q2_all = (2 * p_all).astype(np.float32), (2 * q_all).astype(np.float32)
    # the mean-velocity term w |Va - R Vb|^2 = a0 - 2 h0 cos(theta - phase0)
    va, vb = prepared.mean_velocity[ia], prepared.mean_velocity[ib]
    p0, q0 = w * (va[:, 0] * vb[:, 0] + va[:, 1] * vb[:, 1]), w * (va[:, 1] * vb[:, 0] - va[:, 0] * vb[:, 1])
    a0, h0 = w * ((va**2).sum(axis=1) + (vb**2).sum(axis=1)), np.sqrt(p0 * p0 + q0 * q0)
    # first intervals: the angles where that term alone stays under the limit, in pieces <= 45 degrees
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.where(h0 > 0, (a0 - (limit - floor)) / (2 * h0), -1.0)
    reach = np.arccos(np.clip(cosine, -1.0, 1.0))
    reach[cosine > 1] = 0.0
    pieces = np.where(cosine > 1, 0, np.maximum(1, np.ceil(reach / (math.pi / 8)))).astype(int)
    pair = np.repeat(np.arange(len(ia)), pieces)
    half = (reach / np.maximum(pieces, 1))[pair]
    first = np.cumsum(pieces) - pieces
    centre = np.arctan2(q0, p0)[pair] - reach[pair] + half * (2 * (np.arange(len(pair)) - first[pair]) + 1)
    squares = left_squares.sum(axis=1) + right_squares.sum(axis=1)
    passed = np.zeros(len(ia), dtype=bool)
    for level in range(levels + 1):
        c, s = np.cos(centre), np.sin(centre)
        velocity_term = a0[pair] - 2 * _interval_max(p0[pair] * c + q0[pair] * s, q0[pair] * c - p0[pair] * s, h0[pair], half)
        entries = _entry_minima(a_all[pair], h_all[pair], p2_all[pair], q2_all[pair], centre, half)
        spread = entries.min(axis=2).sum(axis=1) / n
        alive = np.maximum(spread, floor[pair]) + velocity_term <= limit[pair]
        if alive.any():
            # the optimal assignment of the entries' minima bounds much tighter (measured: a cheaper
            # dual of it, row then column reduction, listed twice the pairs for more time)
            ks = np.flatnonzero(alive)
            sigma = np.array([linear_sum_assignment(entries[k])[1] for k in ks])
            rows = np.arange(n)
            matched = entries[ks[:, None], rows, sigma].sum(axis=1) / n
            alive[ks] = np.maximum(matched, floor[pair[ks]]) + velocity_term[ks] <= limit[pair[ks]]
            # that assignment at its own best rotation is a distance some alignment reaches: where it
            # is within the limit, the pair must be listed, and nothing more needs refining
            owner = pair[ks]
            big_p = p_all[owner[:, None], rows, sigma].sum(axis=1) / n + p0[owner]
            big_q = q_all[owner[:, None], rows, sigma].sum(axis=1) / n + q0[owner]
            reached = squares[owner] / n + a0[owner] - 2 * np.hypot(big_p, big_q)
            passed[owner[reached <= limit[owner]]] = True
            alive &= ~passed[pair]
        if level == levels:
            passed[pair[alive]] = True
            break
        pair, half = np.repeat(pair[alive], 2), np.repeat(half[alive] / 2, 2)
        centre = (centre[alive][:, None] + np.array([-1.0, 1.0]) * half[::2, None]).ravel()
    return passed


def _entry_minima(a, h, hc, hs, centre, half):
    """min over |theta - centre| <= half of a - h cos(theta - phase), for stacks (M, N, N) and
    intervals (M,), where hc = h cos(phase) and hs = h sin(phase): the angle nearest to the phase
    inside the interval. With g the angle from the centre to the phase, h cos(g) and h |sin(g)|
    are linear in hc and hs, and cos(g - half) follows from them, so no entry needs a cosine."""
    c, s = np.cos(centre).astype(np.float32)[:, None, None], np.sin(centre).astype(np.float32)[:, None, None]
    cos_half = np.cos(half).astype(np.float32)[:, None, None]
    sin_half = np.sin(half).astype(np.float32)[:, None, None]
    along = hc * c
    along += hs * s  # h cos(g)
    across = hs * c
    across -= hc * s
    np.abs(across, out=across)  # h |sin(g)|
    inside = along >= h * cos_half  # the phase lies in the interval: the entry reaches a - h
    along *= cos_half
    across *= sin_half
    along += across  # h cos(|g| - half)
    np.copyto(along, h, where=inside)
    return np.subtract(a, along, out=along)


def _interval_max(p, q, magnitude, half):
    """max over |delta| <= half (< pi / 2) of p cos(delta) + q sin(delta) (= magnitude cos(delta - phase))."""
    inside = (p > 0) & (np.abs(q) <= p * np.tan(half))
    return np.where(inside, magnitude, p * np.cos(half) + np.abs(q) * np.sin(half))


def _checked_pairs(pairs, k) -> np.ndarray:
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or (pairs.size and (not np.issubdtype(pairs.dtype, np.integer) or pairs.min() < 0 or pairs.max() >= k)):
        raise ValidationError(f"icp-hungarian.pairwise: pairs must be integer indices into the {k} configurations, shape (P, 2); got shape {pairs.shape}")
    return pairs.astype(int)
