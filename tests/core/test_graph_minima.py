"""flockkit.graphs.local_minima and local_minima_of_cells against a cell-by-cell reference."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
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


def test_a_transition_whose_blend_runs_past_the_recording_is_refused_or_dropped():
    """synthesis blends away from the motion after a transition's start: a graph whose transition
    leaves within its blend of the recording's end cannot be played, so it is never made."""
    import attrs

    from flockkit.errors import ValidationError
    from flockkit.graphs import MotionGraph, Walk
    from flockkit.testing import inputs

    graph = inputs.graph()
    motion, last = graph.motion, graph.motion.n_frames - 1
    given = [(t.start, t.end, t.alignment, t.blend) for t in graph.transitions]
    late = (last - 2, 10, inputs._alignment(motion, last - 2, 10), 5)
    assembled = MotionGraph.assemble(motion, [*given, late])
    assert all(t.start + t.blend <= last for t in assembled.transitions) and len(assembled.transitions) == len(given)
    nodes = sorted({*graph.nodes.tolist(), last - 2})
    renumber = {frame: i for i, frame in enumerate(nodes)}
    transitions = [attrs.evolve(t, source=renumber[t.start], target=renumber[t.end]) for t in graph.transitions]
    clips = [
        flockkit.graphs.Clip(source=i, target=i + 1, start=a, stop=b) for i, (a, b) in enumerate(zip(nodes, nodes[1:]))
    ]
    leaving = attrs.evolve(transitions[0], source=renumber[last - 2], start=last - 2)
    with pytest.raises(ValidationError, match=r"transitions\[\d+\] leaves frame 118 with a blend of 5"):
        MotionGraph(motion=motion, nodes=nodes, clips=clips, transitions=[*transitions, leaving])
    assert flockkit.synthesize(assembled, Walk(start=0, edges=[("clip", 0)])).n_frames == 3
