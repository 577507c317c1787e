"""The metric's compiled assignments against scipy's, cold and started from any earlier solution."""

import numpy as np
from flockkit_icp.assignment import assign
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from flockkit.testing import strategies as fst


def _optimum(left, right):
    cost = ((left[:, None, :] - right[None, :, :]) ** 2).sum(axis=2)
    rows, columns = linear_sum_assignment(cost)
    return cost[rows, columns].sum(), cost


def _check(left, right, totals, assignment):
    for p in range(len(left)):
        best, cost = _optimum(left[p], right[p])
        assert sorted(assignment[p]) == list(range(left.shape[1]))  # a permutation
        own = cost[np.arange(left.shape[1]), assignment[p]].sum()
        assert abs(totals[p] - own) <= 1e-12 * (1 + own)  # its own total
        assert totals[p] <= best + 1e-9 * (1 + abs(best))  # optimal


def _stacked(pairs):
    """(left, right) point sets (positions and velocities side by side) of configuration pairs."""
    left = np.stack([np.concatenate([a.positions, a.velocities], axis=1) for a, _ in pairs])
    right = np.stack([np.concatenate([b.positions, b.velocities], axis=1) for _, b in pairs])
    return left, right


def _same_size(count, dims):
    """`count` configurations of one size (1 to 30 agents)."""
    one = lambda n: fst.configurations(min_agents=n, max_agents=n, dims=dims)  # noqa: E731
    return st.integers(1, 30).flatmap(lambda n: st.tuples(*[one(n)] * count))


@settings(max_examples=60, deadline=None)
@given(_same_size(8, 2))
def test_cold_assignments_are_optimal(configs):
    left, right = _stacked(list(zip(configs[::2], configs[1::2])))
    totals, assignment, _ = assign(left, right)
    _check(left, right, totals, assignment)


@settings(max_examples=60, deadline=None)
@given(_same_size(3, 3), st.integers(0, 2**32 - 1))
def test_assignments_started_from_any_earlier_solution_are_optimal(configs, seed):
    """Warm from another problem's solution, and from a random permutation with random duals: the
    start changes the work only, never the optimum."""
    a, b, c = configs
    left, right = _stacked([(a, b)])
    _, assignment, duals = assign(*_stacked([(a, c)]))  # another problem's solution
    totals, found, _ = assign(left, right, assignment, duals, np.array([True]))
    _check(left, right, totals, found)
    rng = np.random.default_rng(seed)
    n = a.n_agents
    assignment, duals = rng.permutation(n)[None].astype(np.int64), rng.normal(scale=10.0, size=(1, n))
    totals, found, _ = assign(left, right, assignment, duals, np.array([True]))
    _check(left, right, totals, found)


def test_ties_and_coincident_points_still_give_a_permutation():
    """All points at one place (every assignment ties), and a square matched to itself turned by
    a quarter turn (four optimal assignments)."""
    square = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    left = np.stack([np.zeros((5, 2)), np.r_[square, [[0.0, 0.0]]]])
    right = np.stack([np.zeros((5, 2)), np.r_[square @ np.array([[0.0, -1.0], [1.0, 0.0]]), [[0.0, 0.0]]]])
    totals, assignment, duals = assign(left, right)
    _check(left, right, totals, assignment)
    assert totals[1] == 0.0
    warm = assign(left, right, assignment.copy(), duals.copy(), np.array([True, True]))
    _check(left, right, warm[0], warm[1])
