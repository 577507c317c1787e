"""The configuration metric of paper 000 section 4.2: ICP alternating with Kuhn-Munkres matching.

E(a, b) = min over rotations R, translations t and one-to-one assignments M of
          (1/N) sum_i |a_i - (R b_M(i) + t)|^2   + velocity_weight * (1/N) sum_i |v_i - R w_M(i)|^2
(velocity_weight = 0 is the paper's E; the default weighs velocities too, see IcpHungarian).

Every agent is matched, so the best translation always maps centroid onto centroid; the search
works on centered positions and alternates the optimal assignment for the current rotation
(`assignment.assign`, compiled, each step started from the last) with the optimal rotation for the current assignment
(Kabsch, proper rotations only) until the distance stops decreasing. Because that only finds a
local minimum, it starts from several rotations and keeps the best: the configuration-space
alignment (section 4.1) and the principal-axes alignment, each also turned by pi about each axis.
Groups of at most MANY_STARTS_UP_TO agents, whose local minima are many and whose assignments are
cheap, start from both alignments turned by every rotation that maps axes onto axes (24 in 3D,
8 in 2D): on unrelated pairs of 4 to 8 agents that found the exact optimum (within 1%) in 198 of
200 cases, against 74 of 100 with the 8 starts (bench/metric.py); so do pairs with a static
configuration (no velocities, so no heading) below PRUNE_FROM agents. In groups of PRUNE_FROM agents
or more only the KEEP starts closest after the first assignment go on descending, which cut the
time per pair at 100 agents from 20-32 to 6-9 ms with the same distances on that bench; a start
whose lower bound there (the mean-velocity term at its rotation, which E holds exactly, plus the
rotation-free bound of the rest) exceeds the KEEP-th distance found is not assigned at all, with
the same result: in recordings, the starts turned away from the heading (at 100 agents 9.4 ->
7.5 assignments a pair near the threshold, 1.5x faster; at 50 agents in 3D 11.6 -> 6.4). The search runs
on many pairs at once (`pairwise`); `compare` is the one-pair case of the same code, so both give
bit-identical distances.

Bounds. With V the mean velocity and d_i = v_i - V the deviations, the velocity term splits
exactly into w |V_a - R V_b|^2 + (w/N) sum_i |d_i - R d'_M(i)|^2 (the deviations sum to zero).
`lower_bound` drops the rotation: sorted distances to the center of mass, sorted deviation
speeds and the difference of mean speeds. `pairs_within` (2D) keeps it: at a fixed rotation one
optimal assignment gives E exactly, and over an interval of rotations the values at its two ends
bound E (E = S - 2 g with g a support function; see `_branch_and_bound`), exactly once both ends
have the same assignment. Intervals whose bound exceeds the threshold are dropped and the others
halved; a pair is listed as soon as a sampled rotation is within the threshold. Blocks of
neighboring configurations are ruled out together first (the triangle inequality). From
SAMPLED_BELOW agents, single pairs are not sampled: an exact evaluation costs less there.
"""

from __future__ import annotations

import functools
import itertools
import math

import attrs
import numba
import numpy as np

import flockkit
from flockkit import rigid, validate
from flockkit.errors import ValidationError

from .assignment import assign, solve, workspace

# Pairs searched together: bounds the (pairs x starts x N x D) arrays of a search step; larger
# chunks were not faster on 2 cores.
_CHUNK = 256
_BOUND_CHUNK = 2048  # pairs bounded together, for the same reason
# Principal spreads within this fraction of the largest count as equal (a symmetric
# configuration); agents' distances within 1e-6 of the group's size count as equal.
_TIED = 1e-6
_ANCHORS = 64  # anchor starts of a symmetric pair, at most
# Small groups start from many rotations (assignments are cheap there and local minima many); in
# groups of PRUNE_FROM agents or more, only the KEEP starts closest after the first assignment go
# on descending (at 20 agents the best start was once 5th after it; at 50 and 100 never below 2nd).
MANY_STARTS_UP_TO = 10
PRUNE_FROM = 40
KEEP = 2
# pairs_within rules out pairs of blocks of neighbors, coarse to fine; 9-3-1 measured fastest of
# the block ladders tried on the 2 000-candidate bench (commit 1dbc1b8)
_BLOCK_SIZES = (9, 3, 1)
# Single pairs are branched and bounded only in groups under SAMPLED_BELOW agents. In larger ones
# the search keeps KEEP starts, so an exact evaluation costs fewer assignments than the branch
# and bound needs to rule a pair out: at 100 agents 1.12 against 1.65 ms for a pair it rules
# out, and a pair it lists (0.56 ms) is evaluated anyway (0.48 ms). There, pairs past the
# rotation-free and mean-velocity bounds are listed as they are: 100 agents, 60 s recording,
# 13.3 -> 10.4 s a build; 50 agents 7.2 -> 6.1 s; 40 agents 3.3 -> 4.1 s, hence 50 (bench/README.md).
SAMPLED_BELOW = 50


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

    velocity_weight: float = validate.parameter("icp-hungarian", default=0.25, minimum=0)
    max_iterations: int = validate.parameter("icp-hungarian", default=50, kind="integer", minimum=1)
    tolerance: float = validate.parameter("icp-hungarian", default=1e-10, minimum=0, strict=True)
    up: tuple = attrs.field(default=flockkit.DEFAULT_UP, converter=tuple)

    capabilities = flockkit.Capabilities(lower_bound=True, pairs_within=True, pairwise=True)

    def compare(self, a: flockkit.Configuration, b: flockkit.Configuration) -> flockkit.Alignment:
        """The alignment of `b` onto `a` with the smallest distance found (see the module docstring)."""
        self._check_pair(a, b)
        prepared = _Prepared([a, b], self.up, self.velocity_weight)
        distance, assignment, rotation = self._search(prepared, np.array([0]), np.array([1]))
        rotation = rotation[0]
        return flockkit.Alignment(
            distance=max(float(distance[0]), 0.0),
            assignment=assignment[0],
            rotation=rotation,
            translation=prepared.com[0] - rotation @ prepared.com[1],
        )

    def pairwise(self, configurations, pairs=None) -> np.ndarray:
        """Distances for many pairs at once, shape (P,): ``compare(c[i], c[j]).distance`` for each
        row (i, j) of `pairs` (shape (P, 2)). Without `pairs`, every i < j in row-major order, the
        condensed form of ``scipy.spatial.distance.pdist`` (``squareform`` makes the matrix)."""
        configurations = self._check_many(configurations)
        k = len(configurations)
        pairs = np.column_stack(np.triu_indices(k, 1)) if pairs is None else _checked_pairs(pairs, k)
        prepared = _Prepared(configurations, self.up, self.velocity_weight)
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
        prepared = _Prepared([a, b], self.up, self.velocity_weight)
        return float(self._rotation_free_bound(prepared, np.array([0]), np.array([1]))[0])

    def pairs_within(self, configurations, threshold: float, *, rows=None) -> np.ndarray:
        """Every pair (i, j), i < j, whose distance may be at most `threshold`, shape (P, 2), sorted:
        pairs left out are proven farther apart (see the module docstring). `rows` = (start, stop)
        keeps the pairs with start <= i < stop, so that workers can share the job.

        Neighboring configurations of a recording are close, which saves most of the work: the
        metric (its exact minimum) obeys the triangle inequality, so if the bound between
        configurations p and q exceeds (sqrt(threshold) + r_p + r_q)^2, where r_p bounds the
        distance from p to each configuration of its block of neighbors (the identity assignment,
        best rotation), no pair of those two blocks can be within the threshold. Blocks of 9, then
        3, then single configurations."""
        configurations = self._check_many(configurations)
        validate.number(threshold, "icp-hungarian.pairs_within: threshold", minimum=0)
        k = len(configurations)
        first, stop = (0, k) if rows is None else (int(rows[0]), int(rows[1]))
        if not 0 <= first <= stop <= k:
            raise ValidationError(
                f"icp-hungarian.pairs_within: rows must be (start, stop) with 0 <= start <= stop <= {k}; got {rows!r}"
            )
        prepared = _Prepared(configurations, self.up, self.velocity_weight)
        limit = float(threshold)
        if prepared.dims == 3:
            i, j = np.triu_indices(k, 1)
            inside = (i >= first) & (i < stop)
            return self._filter(prepared, i[inside], j[inside], limit)
        # the pairs of two blocks of neighbors, coarse to fine: a block pair that is not ruled out
        # as a whole is split into the pairs of its sub-blocks, down to single configurations
        count = -(-k // _BLOCK_SIZES[0])
        p, q = np.triu_indices(count)
        for level, size in enumerate(_BLOCK_SIZES):
            starts = np.arange(0, k, size)
            mine = (starts[p] + size > first) & (starts[p] < stop)
            p, q = p[mine], q[mine]
            if size == 1:
                p, q = p[p < q], q[p < q]
                break
            centres = np.minimum(starts + size // 2, k - 1)
            reach = self._block_reach(prepared, starts, centres, size)
            widened = (math.sqrt(limit) + reach[p] + reach[q]) ** 2
            p, q = self._filter(prepared, centres[p], centres[q], widened, blocks=(p, q)).T
            ratio = size // _BLOCK_SIZES[level + 1]
            offsets = np.arange(ratio)
            p, q = (p[:, None, None] * ratio + offsets[:, None]), (q[:, None, None] * ratio + offsets[None, :])
            p, q = (np.broadcast_to(x, (len(x), ratio, ratio)).ravel() for x in (p, q))
            inside = (p <= q) & (q < -(-k // _BLOCK_SIZES[level + 1]))
            p, q = p[inside], q[inside]
        listed = self._filter(prepared, p, q, np.full(len(p), limit))
        return listed[np.lexsort((listed[:, 1], listed[:, 0]))]

    def _filter(self, prepared, ia, ib, limit, blocks=None) -> np.ndarray:
        """Rows of (ia, ib) (or of `blocks`) whose pair may be within `limit` (one per pair)."""
        ia, ib = np.asarray(ia), np.asarray(ib)
        # rounding must never drop a pair at the limit: allow for it relative to the pair's size
        limit = limit * (1 + 1e-9) + 1e-9 * (
            prepared.scale[ia]
            + prepared.scale[ib]
            + self.velocity_weight * (prepared.speed_scale[ia] + prepared.speed_scale[ib])
        )
        keep = np.zeros(len(ia), dtype=bool)
        for s in range(0, len(ia), _BOUND_CHUNK):
            part = slice(s, s + _BOUND_CHUNK)
            floor = self._rotation_free_bound(prepared, ia[part], ib[part], mean_velocity=False)
            mean_part = self.velocity_weight * (prepared.mean_speed[ia[part]] - prepared.mean_speed[ib[part]]) ** 2
            kept = np.flatnonzero(floor + mean_part <= limit[part])
            if prepared.dims == 2 and len(kept):
                sample = blocks is not None or prepared.n_agents < SAMPLED_BELOW
                kept = kept[
                    _branch_and_bound(prepared, ia[part][kept], ib[part][kept], limit[part][kept], floor[kept], sample)
                ]
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
        rotation = rigid.kabsch(target, source)
        return np.sqrt(((target - _rotate(source, rotation)) ** 2).sum(axis=(1, 2)) / prepared.n_agents)

    # -- internals -------------------------------------------------------------------------

    def _check_pair(self, a, b):
        for name, value in (("a", a), ("b", b)):
            if not isinstance(value, flockkit.Configuration):
                raise ValidationError(
                    f"icp-hungarian: {name} must be a flockkit.Configuration; got {type(value).__name__}"
                )
        if a.positions.shape != b.positions.shape:
            raise ValidationError(
                f"icp-hungarian compares configurations of the same size; got {a.n_agents} agents in {a.dims}D "
                f"and {b.n_agents} in {b.dims}D"
            )

    def _check_many(self, configurations) -> list:
        configurations = list(configurations)
        for index, config in enumerate(configurations):
            if not isinstance(config, flockkit.Configuration):
                raise ValidationError(
                    f"icp-hungarian: configurations[{index}] must be a flockkit.Configuration; got "
                    f"{type(config).__name__}"
                )
            self._check_pair(configurations[0], config)
        return configurations

    def _rotation_free_bound(self, prepared, ia, ib, mean_velocity=True) -> np.ndarray:
        """lower_bound for the pairs (ia[p], ib[p]) (without the mean velocities' part if asked)."""
        n, w = prepared.n_agents, self.velocity_weight
        bound = ((prepared.sorted_radii[ia] - prepared.sorted_radii[ib]) ** 2).sum(axis=1) / n
        if w:
            bound += (
                w * ((prepared.sorted_deviation_speeds[ia] - prepared.sorted_deviation_speeds[ib]) ** 2).sum(axis=1) / n
            )
            if mean_velocity:
                bound += w * (prepared.mean_speed[ia] - prepared.mean_speed[ib]) ** 2
        return bound

    def _search(self, prepared, ia, ib):
        """ICP from every start for pairs (ia[p], ib[p]): (distances, assignments, rotations) of the
        best. Pairs with a static configuration (no heading) get their own starts, searched apart."""
        static = prepared.static[ia] | prepared.static[ib]
        n, d = prepared.n_agents, prepared.dims
        distance, assignment, rotation = np.empty(len(ia)), np.empty((len(ia), n), dtype=int), np.empty((len(ia), d, d))
        for kind in np.unique(static):
            mine = static == kind
            starts = prepared.starts(ia[mine], ib[mine], static=bool(kind))
            distance[mine], assignment[mine], rotation[mine] = self._search_from(prepared, ia[mine], ib[mine], starts)
        for p in np.flatnonzero(prepared.symmetric[ia] | prepared.symmetric[ib]):
            starts = prepared.anchor_starts(ia[p], ib[p])
            if len(starts):
                found = self._search_from(prepared, ia[p : p + 1], ib[p : p + 1], starts[None])
                if found[0][0] < distance[p]:
                    distance[p], assignment[p], rotation[p] = (value[0] for value in found)
        return distance, assignment, rotation

    def _search_from(self, prepared, ia, ib, starts):
        """ICP from `starts` (P, S, D, D) for pairs (ia[p], ib[p]): the best of each pair."""
        p, s, d = starts.shape[0], starts.shape[1], prepared.dims
        pick = lambda array, index: np.repeat(array[index], s, axis=0)  # noqa: E731
        distance, assignment, rotation = self._descend(
            pick(prepared.centered, ia),
            pick(prepared.centered, ib),
            pick(prepared.velocities, ia),
            pick(prepared.velocities, ib),
            starts.reshape(p * s, d, d),
            group=s,
            floor=np.repeat(self._rotation_free_bound(prepared, ia, ib, mean_velocity=False), s),
        )
        best = np.argmin(distance.reshape(p, s), axis=1)  # the first start wins ties
        flat = np.arange(p) * s + best
        return distance[flat], assignment[flat], rotation[flat]

    def _descend(self, pa, pb, va, vb, rotation, group=1, floor=None):
        """Alternate assignment and rotation from each start until its distance stops falling; of
        each `group` of starts (one pair's), only the KEEP best after the first assignment go on
        (`floor`, a bound per start without the mean velocities, spares starts that cannot be).
        Each start's assignment after the first starts from its last one (`assign`, warm)."""
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
        solved = _Solved(m, n)
        prune = n >= PRUNE_FROM and group > KEEP
        for step in range(self.max_iterations):
            if step == 0 and prune:
                active, distance, assignment = self._first_assignments(left, pb, va, vb, rotation, group, floor, solved)
            else:
                distance, assignment = self._assign(left, pb, vb, rotation, active, solved)
            previous = best[active]
            improved = distance < previous
            better = active[improved]
            # an unchanged assignment gives back the same rotation: nothing more to gain
            moved = np.any(assignment != best_assignment[active], axis=1) | ~np.isfinite(previous)
            best[better], best_assignment[better], best_rotation[better] = (
                distance[improved],
                assignment[improved],
                rotation[better],
            )
            going = improved & moved & (distance < previous * (1 - self.tolerance))
            if step == 0 and prune:  # after the first assignment (starts not assigned rank last)
                first = np.full(m, np.inf)
                first[active] = distance
                going &= _ranks(first, group)[active] < KEEP
            active, assignment = active[going], assignment[going]
            if not len(active):
                break
            target, source = pa[active], _gather(pb[active], assignment)
            if w:  # the velocity term as extra rows weighted by root(w)
                target = np.concatenate([target, root * va[active]], axis=1)
                source = np.concatenate([source, root * _gather(vb[active], assignment)], axis=1)
            rotation[active] = rigid.kabsch(target, source)
        return best, best_assignment, best_rotation

    def _assign(self, left, pb, vb, rotation, rows, solved):
        """(distance, optimal assignment) at the rotation of each of `rows`, each started from
        its row's last solution in `solved` where it has one."""
        w = self.velocity_weight
        right = _rotate(pb[rows], rotation[rows])
        if w:
            right = np.concatenate([right, math.sqrt(w) * _rotate(vb[rows], rotation[rows])], axis=2)
        return solved.assign(left[rows], right, rows)

    def _first_assignments(self, left, pb, va, vb, rotation, group, floor, solved):
        """(rows, distances, assignments) of the first assignment of only the starts that may rank
        among their pair's KEEP best after it, so that the others are never assigned. A start's
        distance is at least `floor` plus w |Va - R Vb|^2 at its rotation R (the velocity cost
        holds that mean-velocity term exactly: the deviations from the mean sum to zero). Starts
        are assigned lowest bound first; one whose bound exceeds the KEEP-th distance found would
        rank below it, so the result is the same as assigning every start. In a recording, the
        starts turned half a turn from the heading are spared this way."""
        m, n = left.shape[:2]
        turned = np.einsum("mij,mj->mi", rotation, vb.mean(axis=1))
        bound = floor + self.velocity_weight * ((va.mean(axis=1) - turned) ** 2).sum(axis=1)
        bound = bound * (1 - 1e-9) - 1e-12  # rounding must never spare a start that could rank
        distance, assignment = np.full(m, np.inf), np.tile(np.arange(n), (m, 1))
        take = _ranks(bound, group) < KEEP
        while take.any():
            rows = np.flatnonzero(take)
            distance[rows], assignment[rows] = self._assign(left, pb, vb, rotation, rows, solved)
            kept = np.partition(distance.reshape(-1, group), KEEP - 1, axis=1)[:, KEEP - 1]
            take = np.isinf(distance) & (bound <= np.repeat(kept, group))
        rows = np.flatnonzero(np.isfinite(distance))
        return rows, distance[rows], assignment[rows]


class _Solved:
    """The last assignment and duals of each of m problems, so that the next assignment of a
    problem starts from them (`assignment.assign`)."""

    def __init__(self, m, n):
        self.assignment, self.duals = np.empty((m, n), dtype=np.int64), np.empty((m, n))
        self.warm = np.zeros(m, dtype=bool)

    def assign(self, left, right, rows):
        """(mean cost, assignment) of problems `rows` with these point sets, remembered."""
        totals, self.assignment[rows], self.duals[rows] = assign(
            left, right, self.assignment[rows], self.duals[rows], self.warm[rows]
        )
        self.warm[rows] = True
        return totals / left.shape[1], self.assignment[rows]


class _Prepared:
    """Per-configuration arrays for a list of same-sized configurations."""

    def __init__(self, configurations, up, velocity_weight):
        self.velocity_weight = velocity_weight
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
        radii = np.linalg.norm(self.centered, axis=2)
        self.radius_order = np.argsort(radii, axis=1, kind="stable")
        self.sorted_radii = np.take_along_axis(radii, self.radius_order, axis=1)
        self.sorted_deviation_speeds = np.sort(np.linalg.norm(self.deviations, axis=2), axis=1)
        self.scale = (self.centered**2).sum(axis=(1, 2)) / self.n_agents  # mean squared radius
        self.speed_scale = (self.velocities**2).sum(axis=(1, 2)) / self.n_agents
        self.static = ~self.velocities.any(axis=(1, 2))  # no heading: its frame is the world's axes
        self.radii = radii
        spreads = np.linalg.eigvalsh(np.transpose(self.centered, (0, 2, 1)) @ self.centered)  # ascending
        gaps = np.diff(spreads, axis=1).min(axis=1)
        # two equal spreads: the principal axes are any pair in a plane, not a start to trust
        self.symmetric = gaps <= _TIED * spreads[:, -1]

    @functools.cached_property
    def turned_together(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions and sqrt(velocity_weight) * velocity deviations side by side (K, N, 4), as the
        branch and bound turns them, and each configuration's sum of their squares (K,): made once
        for all the bounding calls of a `pairs_within`."""
        stacked = np.concatenate([self.centered, math.sqrt(self.velocity_weight) * self.deviations], axis=2)
        return stacked, (stacked**2).sum(axis=(1, 2))

    def starts(self, ia, ib, static=False) -> np.ndarray:
        """Start rotations (P, S, D, D): the configuration frames aligned, then the principal axes
        aligned, each turned by each half turn, or in small groups by each rotation that maps axes
        onto axes (the principal axes' order and signs are arbitrary where spreads are close). So
        are `static` pairs (a configuration without velocities, whose frame is the world's axes)
        below PRUNE_FROM agents: at 20 agents, 8 starts left one unrelated pair of 40 5% above rmsd's
        best; these (48 in 3D, 3x the time) none (bench/metric.py). Static pairs also start from
        the best rotation for the agents matched in the order of their distances to the centre of
        mass (rmsd's "distance" method): 1 unrelated pair of 40 at 10 agents was 4.3% above that
        method's E with the 48 starts alone, and descending from its rotation can only go lower."""
        many = self.n_agents <= MANY_STARTS_UP_TO or (static and self.n_agents < PRUNE_FROM)
        turns = _axis_turns(self.dims) if many else _half_turns(self.dims)
        starts = [np.transpose(axes[ia], (0, 2, 1)) @ turn @ axes[ib]
                  for turn in turns for axes in (self.frames, self.principal)]  # fmt: skip
        if static:
            starts.append(rigid.kabsch(_gather(self.centered[ia], self.radius_order[ia]),
                                       _gather(self.centered[ib], self.radius_order[ib])))  # fmt: skip
        return np.stack(starts, axis=1)

    def anchor_starts(self, i, j) -> np.ndarray:
        """Start rotations (S, D, D) for a pair with a symmetric configuration (equal principal
        spreads: a square, a regular polygon, a grid), whose principal axes say nothing. In `i`,
        a frame is fixed by the agent farthest from the centre of mass and, in 3D, the one farthest
        from that agent's axis; every pair of agents of `j` at the same distances (to within 1e-6
        of the group's size) gives the frame a rigid copy would have, so one of these starts (at
        most _ANCHORS) is the copy's rotation, and descending from it finds distance zero."""
        a, b = self.centered[i], self.centered[j]
        close = lambda x, y: np.abs(x - y) <= 1e-6 * math.sqrt(max(self.scale[i], self.scale[j]))  # noqa: E731
        first = int(np.argmax(self.radii[i]))
        if close(self.radii[i][first], 0.0):  # every agent on the centre of mass: any rotation is exact
            return np.empty((0, self.dims, self.dims))
        candidates = np.flatnonzero(close(self.radii[j], self.radii[i][first]))
        if self.dims == 2:
            pairs = [(c, None) for c in candidates]
            second = None
        else:
            height_a, off_a = _about_axis(a, a[first])
            second = int(np.argmax(off_a))
            if close(off_a[second], 0.0):  # collinear: the turn about the line is free
                pairs, second = [(c, None) for c in candidates], None
            else:
                pairs = []
                for c in candidates:
                    height_b, off_b = _about_axis(b, b[c])
                    match = close(off_b, off_a[second]) & close(height_b, height_a[second])
                    pairs += [(c, other) for other in np.flatnonzero(match)]
        frame_a = _anchor_frame(a[first], None if second is None else a[second])
        frames_b = [_anchor_frame(b[c], None if other is None else b[other]) for c, other in pairs[:_ANCHORS]]
        return np.transpose(frame_a) @ np.stack(frames_b) if frames_b else np.empty((0, self.dims, self.dims))


def _about_axis(points, toward) -> tuple[np.ndarray, np.ndarray]:
    """Each point's height along the axis from the origin toward `toward`, and distance from it."""
    axis = toward / np.linalg.norm(toward)
    height = points @ axis
    return height, np.linalg.norm(points - np.outer(height, axis), axis=1)


def _anchor_frame(first, second=None) -> np.ndarray:
    """Rows: a proper orthonormal frame whose first axis points at `first` and, in 3D, whose
    second lies towards `second` (any direction across `first` without it)."""
    x = first / np.linalg.norm(first)
    if len(x) == 2:
        return np.array([x, [-x[1], x[0]]])
    if second is None:
        second = np.eye(3)[int(np.argmin(np.abs(x)))]
    y = second - (second @ x) * x
    y /= np.linalg.norm(y)
    return np.array([x, y, np.cross(x, y)])


def exact_distance(a: np.ndarray, b: np.ndarray) -> float:
    """E without velocities by enumeration, for small groups (N!): every assignment of `b`'s
    points (N, D) to `a`'s, each with its best proper rotation (batched Kabsch). The reference
    the metric's search is checked against (tests, bench/metric.py)."""
    a, b = a - a.mean(axis=0), b - b.mean(axis=0)
    orders = np.array(list(itertools.permutations(range(len(a)))))
    best = np.inf
    for chunk in np.array_split(orders, max(1, len(orders) // 5000)):
        source = b[chunk]
        placed = rigid.rotate(rigid.kabsch(np.broadcast_to(a, source.shape), source)[:, None], source)
        best = min(best, float(np.min(np.mean(np.sum((placed - a) ** 2, axis=2), axis=1))))
    return best


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


def _axis_turns(d: int) -> list[np.ndarray]:
    """The proper rotations that map coordinate axes onto coordinate axes (24 in 3D; in 2D the 8
    turns by multiples of pi/4, the 4 axis turns and the diagonals between them)."""
    if d == 2:
        return [np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]) for a in np.arange(8) * math.pi / 4]
    turns = []
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            turn = np.zeros((3, 3))
            turn[range(3), order] = signs
            if np.linalg.det(turn) > 0:
                turns.append(turn)
    return turns


def _rotate(points, rotation):
    """points @ rotation.T for stacks (M, N, D) and (M, D, D)."""
    return rigid.rotate(rotation[:, None], points)


def _ranks(values, group) -> np.ndarray:
    """Each value's rank (0 lowest) within its run of `group` consecutive values (one pair's starts)."""
    return np.argsort(np.argsort(values.reshape(-1, group), axis=1), axis=1).ravel()


def _gather(points, assignment):
    return np.take_along_axis(points, assignment[:, :, None], axis=1)


def _branch_and_bound(prepared, ia, ib, limit, floor, sample=True, levels=12) -> np.ndarray:
    """Mask over pairs (ia, ib) (2D): True where some rotation may keep E <= limit (one limit per
    pair). `floor` bounds the position and deviation part for every rotation; without `sample`,
    only the mean-velocity term's range of rotations (below) is checked.

    At a fixed rotation theta, E(theta) = S - 2 g(theta), where S does not depend on theta and
    g(theta) = max over assignments s of <z_s, u(theta)>, z_s the 2D vector of the assignment's
    cross terms: g is the support function of a convex polygon. One optimal assignment at theta
    gives E(theta) exactly. Over an interval [t1, t2] (narrower than pi) the polygon lies in the
    wedge {<x, u(t1)> <= g(t1), <x, u(t2)> <= g(t2)}, so g is at most the wedge apex's support:
    a lower bound on E over the interval from its two ends alone. It is exact when both ends have
    the same optimal assignment (that vertex is then the apex), so intervals are halved until
    their bound exceeds the limit, or their ends agree, or a sampled E(theta) is within it (pair by
    pair, compiled: `_bound_pairs`)."""
    stacked, squares = prepared.turned_together
    w = prepared.velocity_weight
    # the mean-velocity term w |Va - R Vb|^2 = a0 - 2 (p0 cos(theta) + q0 sin(theta))
    va, vb = prepared.mean_velocity[ia], prepared.mean_velocity[ib]
    p0, q0 = w * (va[:, 0] * vb[:, 0] + va[:, 1] * vb[:, 1]), w * (va[:, 1] * vb[:, 0] - va[:, 0] * vb[:, 1])
    a0, h0 = w * ((va**2).sum(axis=1) + (vb**2).sum(axis=1)), np.hypot(p0, q0)
    total = (squares[ia] + squares[ib]) / prepared.n_agents + a0  # S
    # only angles where the mean-velocity term alone stays under the limit, in an even number of
    # pieces <= pi / 2 about the angle phi that aligns the mean velocities
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        cosine = np.where(h0 > 0, (a0 - (limit - floor)) / (2 * h0), -1.0)
    reach, phi = np.arccos(np.clip(cosine, -1.0, 1.0)), np.arctan2(q0, p0)
    pieces = np.where(cosine > 1, 0, 2 * np.maximum(1, np.ceil(reach / (math.pi / 2)))).astype(np.int64)
    if not sample:
        return pieces > 0
    passed = np.zeros(len(ia), dtype=bool)
    _bound_pairs(stacked, ia, ib, total, a0, p0, q0, phi, reach, pieces, np.asarray(limit, float), levels, passed)
    return passed


@numba.njit(cache=True, nogil=True)
def _sample(left, right, theta, a0, p0, q0, assignment, turned, duals, work):
    """E(theta) of one pair (its optimal assignment into `assignment`): `right` (N, 4: x, y, dx,
    dy) turned by theta in both planes, solved from nothing (started from the assignment at an
    interval's end instead, a sample took as long at 20 and 100 agents)."""
    c, s = math.cos(theta), math.sin(theta)
    for j in range(right.shape[0]):
        turned[j, 0] = c * right[j, 0] - s * right[j, 1]
        turned[j, 1] = s * right[j, 0] + c * right[j, 1]
        turned[j, 2] = c * right[j, 2] - s * right[j, 3]
        turned[j, 3] = s * right[j, 2] + c * right[j, 3]
    return solve(left, turned, assignment, duals, False, work) / left.shape[0] + a0 - 2 * (p0 * c + q0 * s)


@numba.njit(cache=True, nogil=True)
def _bound_pairs(stacked, ia, ib, total, a0, p0, q0, phi, reach, pieces, limit, levels, passed):
    """The branch and bound of `_branch_and_bound`, pair by pair: a sample at phi (a pair within
    the limit nearly always is within there, so one assignment lists it), then at the pieces'
    ends, then the pieces halved depth first (lower half first) until a sample is within the
    limit, an interval's ends agree with its bound within it, or an interval is `levels` halvings
    deep with its bound within it (listed: undecided); a pair is listed on the first."""
    n = stacked.shape[1]
    work, turned, duals = workspace(n), np.empty((n, 4)), np.empty(n)
    most = max(1, pieces.max())
    depth = most + levels + 1  # each halving replaces one interval by two
    ends, end_theta, end_value = np.empty((most + 1, n), np.int64), np.empty(most + 1), np.empty(most + 1)
    lo, hi, lo_value, hi_value = np.empty(depth), np.empty(depth), np.empty(depth), np.empty(depth)
    lo_assignment, hi_assignment = np.empty((depth, n), np.int64), np.empty((depth, n), np.int64)
    level, middle = np.empty(depth, np.int64), np.empty(n, np.int64)
    for p in range(len(ia)):
        k = pieces[p]
        if k == 0:
            continue
        left, right, bound = stacked[ia[p]], stacked[ib[p]], limit[p]
        centre = k // 2
        end_theta[centre] = phi[p]
        end_value[centre] = _sample(left, right, phi[p], a0[p], p0[p], q0[p], ends[centre], turned, duals, work)
        if end_value[centre] <= bound:
            passed[p] = True
            continue
        for e in range(k + 1):
            if e != centre:
                end_theta[e] = phi[p] - reach[p] + e * (2 * reach[p] / k)
                end_value[e] = _sample(left, right, end_theta[e], a0[p], p0[p], q0[p], ends[e], turned, duals, work)
                if end_value[e] <= bound:
                    passed[p] = True
                    break
        if passed[p]:
            continue
        top = 0
        for e in range(k - 1, -1, -1):
            lo[top], hi[top] = end_theta[e], end_theta[e + 1]
            lo_value[top], hi_value[top] = end_value[e], end_value[e + 1]
            lo_assignment[top], hi_assignment[top], level[top] = ends[e], ends[e + 1], 0
            top += 1
        while top > 0 and not passed[p]:
            top -= 1
            if not _wedge_bound(total[p], lo[top], hi[top], lo_value[top], hi_value[top]) <= bound:
                continue
            same = True
            for i in range(n):
                if lo_assignment[top, i] != hi_assignment[top, i]:
                    same = False
                    break
            if same or level[top] == levels:  # the bound is reached inside, or still undecided
                passed[p] = True
                break
            half = 0.5 * (lo[top] + hi[top])
            value = _sample(left, right, half, a0[p], p0[p], q0[p], middle, turned, duals, work)
            if value <= bound:
                passed[p] = True
                break
            # the upper half below the lower, so that the lower is taken next
            lo[top + 1], hi[top + 1], lo_value[top + 1], hi_value[top + 1] = lo[top], half, lo_value[top], value
            lo_assignment[top + 1], hi_assignment[top + 1] = lo_assignment[top], middle
            lo[top], lo_value[top], lo_assignment[top] = half, value, middle
            level[top + 1] = level[top] = level[top] + 1
            top += 2


@numba.njit(cache=True, error_model="numpy")
def _wedge_bound(total, lo, hi, lo_value, hi_value):
    """Lower bound on E(theta) = total - 2 g(theta) over [lo, hi] (narrower than pi), g a support
    function, from E at the two ends: g is at most the support of the apex of the wedge
    {<x, u(lo)> <= g(lo), <x, u(hi)> <= g(hi)}, which is |apex| where the apex lies in the
    interval's directions, else the larger end value (and for an interval of one angle, which
    has no apex)."""
    half = (hi - lo) / 2
    g1, g2 = (total - lo_value) / 2, (total - hi_value) / 2
    x, y = (g1 + g2) / (2 * math.cos(half)), (g2 - g1) / (2 * math.sin(half))  # apex, axes along the middle
    if abs(math.atan2(y, x)) <= half:
        return total - 2 * math.hypot(x, y)
    return total - 2 * max(g1, g2)


def _checked_pairs(pairs, k) -> np.ndarray:
    pairs = np.asarray(pairs)
    if (
        pairs.ndim != 2
        or pairs.shape[1] != 2
        or (pairs.size and (not np.issubdtype(pairs.dtype, np.integer) or pairs.min() < 0 or pairs.max() >= k))
    ):
        raise ValidationError(
            f"icp-hungarian.pairwise: pairs must be integer indices into the {k} configurations, shape (P, 2); got "
            f"shape {pairs.shape}"
        )
    return pairs.astype(int)
