"""flockkit.graphs.local_minima and local_minima_of_cells against a cell-by-cell reference."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from flockkit.graphs import local_minima, local_minima_of_cells
from flockkit.testing import strategies as fst


def reference(values, far):
    """Each finite off-diagonal far cell compared with each of its 8 neighbors, one at a time."""
    k, found = len(values), []
    for i in range(k):
        for j in range(k):
            if i == j or not far[i, j] or not np.isfinite(values[i, j]):
                continue
            neighbors = [
                values[i + di, j + dj]
                for di in (-1, 0, 1)
                for dj in (-1, 0, 1)
                if (di or dj) and 0 <= i + di < k and 0 <= j + dj < k and i + di != j + dj
            ]
            if all(values[i, j] <= n for n in neighbors):
                found.append((i, j))
    return found


@settings(max_examples=200, deadline=None)
@given(fst.difference_matrices(max_size=12), st.integers(0, 3))
def test_local_minima_are_the_cells_at_most_their_neighbors(values, apart):
    k = len(values)
    far = np.abs(np.subtract.outer(np.arange(k), np.arange(k))) >= apart
    expected = reference(values, far)
    assert local_minima(values, far) == expected
    # given as cells: every finite cell, in any order, gives the same minima in row-major order
    rows, cols = np.nonzero(np.isfinite(values))
    shuffled = np.random.default_rng(k).permutation(len(rows))
    rows, cols = rows[shuffled], cols[shuffled]
    got = local_minima_of_cells(rows, cols, values[rows, cols], far[rows, cols])
    assert [tuple(map(int, cell)) for cell in got] == expected
