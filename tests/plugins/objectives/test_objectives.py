import math
from unittest import mock

import numpy as np
import pytest
from flockkit_objectives import terms
from flockkit_objectives.terms import count_flocks
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit import Ball, ComConstraint, Motion, Polygon, Problem, ShapeConstraint
from flockkit.testing import strategies


def still(positions, frames=5):
    return Motion(positions=np.repeat(np.asarray(positions, float)[None], frames, axis=0), dt=0.1)


def test_com_term_is_the_gaussian_log_density_at_its_frame():
    motion = still([[0, 0], [2, 0], [4, 3]])
    problem = Problem(
        n_agents=3,
        duration=0.4,
        constraints=[ComConstraint(agents=[0, 1], time=0.2, position=[1, 0.5], velocity=[1, 0])],
    )
    terms = flockkit.get("objective", "com").log_terms(motion, problem)
    expected = -math.log(0.1 * math.sqrt(2 * math.pi)) - 0.25 / (2 * 0.01)
    assert terms[2] == pytest.approx(expected) and np.count_nonzero(terms) == 1


def test_shape_term_counts_squared_distance_outside_only():
    triangle = Polygon(vertices=[[0, 0], [4, 0], [0, 4]])
    motion = still([[1, 1], [0.5, 0.5], [0, 6]])  # the third agent is 2 above the top corner
    problem = Problem(
        n_agents=3, duration=0.4, constraints=[ShapeConstraint(time=0.3, shape=triangle, velocity=[1, 0])]
    )
    terms = flockkit.get("objective", "shape").log_terms(motion, problem)
    assert terms[3] == pytest.approx(-10.0 * 4.0) and np.count_nonzero(terms) == 1
    inside = Problem(
        n_agents=3,
        duration=0.4,
        constraints=[ShapeConstraint(agents=[0, 1], time=0.3, shape=triangle, velocity=[1, 0])],
    )
    assert not np.any(flockkit.get("objective", "shape").log_terms(motion, inside))


def test_shape_term_in_3d_with_a_ball():
    motion = still([[0, 0, 0], [0, 0, 3]])
    problem = Problem(
        n_agents=2,
        dims=3,
        duration=0.4,
        shape_weight=2.0,
        constraints=[ShapeConstraint(time=0.0, shape=Ball(center=[0, 0, 0], radius=1.0), velocity=[1, 0, 0])],
    )
    assert flockkit.get("objective", "shape").log_terms(motion, problem)[0] == pytest.approx(-2.0 * 4.0)


@pytest.mark.parametrize("preferred, expected", [(1, -1000.0), (2, 0.0), (3, -1000.0)])
def test_flock_term_counts_groups_that_cannot_see_each_other(preferred, expected):
    motion = still([[0, 0], [1, 0], [2, 0], [20, 0], [21, 0]])
    problem = Problem(n_agents=5, duration=0.4, flocks=preferred, visibility=1.5)
    terms = flockkit.get("objective", "flocks").log_terms(motion, problem)
    np.testing.assert_array_equal(terms, np.full(5, expected))


@settings(max_examples=40, deadline=None)
@given(motion=strategies.motions(max_frames=6, max_agents=12, max_coordinate=5.0), visibility=st.floats(0.1, 4.0))
def test_flocks_counted_over_many_frames_at_once_are_each_frames_own_count(motion, visibility):
    """count_flocks over (F, N, D) in one graph equals, frame by frame, a union-find of its own,
    whether the frames are counted in one block or in blocks of a few."""
    counts = count_flocks(motion.positions, visibility)
    with mock.patch.object(terms, "_PAIRS_PER_BLOCK", 2 * motion.n_agents**2):
        np.testing.assert_array_equal(count_flocks(motion.positions, visibility), counts)
    for frame, count in zip(motion.positions, counts):
        parent = list(range(len(frame)))

        def root(a, parent=parent):
            while parent[a] != a:
                a = parent[a]
            return a

        for a in range(len(frame)):
            for b in range(a):
                if np.linalg.norm(frame[a] - frame[b]) < visibility:
                    parent[root(a)] = root(b)
        assert count == len({root(a) for a in range(len(frame))}) == count_flocks(frame, visibility)
