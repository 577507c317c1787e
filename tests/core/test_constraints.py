import numpy as np
import pytest
from hypothesis import given, settings

import flockkit
from flockkit import ComConstraint, PointConstraint, Polygon, Problem, ShapeConstraint
from flockkit.constrained import windows
from flockkit.constrained.problem import track_path
from flockkit.errors import ValidationError
from flockkit.testing import strategies as fst


def point(agent, time, position, velocity=None):
    return PointConstraint(agent=agent, time=time, position=position, velocity=velocity)


def test_frames_follow_round_time_over_dt():
    problem = Problem(n_agents=3, dt=0.1, duration=2.04)
    assert problem.n_frames == 21 and problem.frame(0.96) == 10


def test_velocities_come_from_the_spline_through_a_sequence():
    # positions on a line at constant velocity, which the spline through four points reproduces
    track = [point(0, t, [2.0 * t, 1.0 - t]) for t in (0.0, 1.0, 2.0, 3.0)]
    problem = Problem(n_agents=2, duration=3.0, constraints=track)
    for filled in problem.constraints:
        np.testing.assert_allclose(filled.velocity, [2.0, -1.0], atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(track=fst.com_tracks(min_constraints=4, max_constraints=6, max_coordinate=5.0))
def test_a_track_path_through_four_or_more_bends_least(track):
    """Through four or more positions the path is the natural cubic: no acceleration at its ends,
    and no more integrated squared acceleration than scipy's default (not-a-knot) cubic."""
    from scipy.interpolate import make_interp_spline

    times, positions = [c.time for c in track], np.array([c.position for c in track])
    path = track_path(times, positions)
    np.testing.assert_allclose(path(times), positions, atol=1e-9)
    scale = 1 + np.abs(positions).max()
    np.testing.assert_allclose(path([times[0], times[-1]], 2), 0.0, atol=1e-9 * scale)
    samples = np.linspace(times[0], times[-1], 2001)

    def bending(spline):
        return float(np.sum(spline(samples, 2) ** 2))

    assert bending(path) <= bending(make_interp_spline(times, positions, k=3)) * (1 + 1e-9) + 1e-9


def test_a_given_velocity_is_kept_and_two_constraints_give_the_chord():
    problem = Problem(
        n_agents=2, duration=2.0, constraints=[point(1, 0.0, [0, 0], velocity=[5, 5]), point(1, 2.0, [4, 2])]
    )
    np.testing.assert_allclose(problem.constraints[0].velocity, [5, 5])
    np.testing.assert_allclose(problem.constraints[1].velocity, [2, 1])


def test_com_sequences_are_fitted_per_subset():
    problem = Problem(
        n_agents=4,
        duration=2.0,
        constraints=[
            ComConstraint(agents=[0, 1], time=0.0, position=[0, 0]),
            ComConstraint(agents=[0, 1], time=1.0, position=[3, 0]),
            ComConstraint(time=0.5, position=[0, 0], velocity=[0, 1]),
        ],
    )
    np.testing.assert_allclose(problem.constraints[0].velocity, [3, 0])
    np.testing.assert_allclose(problem.constraints[2].velocity, [0, 1])


@pytest.mark.parametrize(
    "constraints, match",
    [
        ([point(0, 1.0, [0, 0])], "only point constraint on agent 0"),
        ([ComConstraint(time=1.0, position=[0, 0])], "only COM constraint"),
        ([point(5, 1.0, [0, 0], [1, 0])], "agent 5 does not exist"),
        ([point(0, 9.0, [0, 0], [1, 0])], "after the end"),
        ([point(0, 1.0, [0, 0, 0], [1, 0, 0])], "3D in a 2D problem"),
        ([point(0, 1.0, [0, 0], [1, 0]), point(0, 1.04, [1, 0], [1, 0])], "same agents at frame 10"),
        (["not a constraint"], r"constraints\[0\]"),
    ],
)
def test_bad_constraints_are_named(constraints, match):
    with pytest.raises(ValidationError, match=match):
        Problem(n_agents=3, duration=4.0, constraints=constraints)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: PointConstraint(agent=-1, time=0, position=[0, 0]), "agent"),
        (lambda: PointConstraint(agent=0, time=-1, position=[0, 0]), "time"),
        (lambda: PointConstraint(agent=0, time=0, position=[0, np.nan]), "position"),
        (lambda: PointConstraint(agent=0, time=0, position=[0, 0], velocity=[1, 0, 0]), "velocity"),
        (lambda: ComConstraint(agents=[1, 1], time=0, position=[0, 0]), "agents"),
        (lambda: ShapeConstraint(time=0, shape="square", velocity=[1, 0]), "shape"),
        (lambda: ShapeConstraint(time=0, shape=flockkit.Ball(center=[0, 0], radius=1)), "velocity"),
        (lambda: Problem(n_agents=0, duration=1.0), "n_agents"),
        (lambda: Problem(n_agents=2, dims=4, duration=1.0), "dims"),
        (lambda: Problem(n_agents=2, duration=0.0), "duration"),
        (lambda: Problem(n_agents=2, duration=1.0, obstacles=[flockkit.Ball(center=[0, 0, 0], radius=1)]), "obstacles"),
        (lambda: Problem(n_agents=2, duration=1.0, sigma_com=0), "sigma_com"),
        (lambda: Problem(n_agents=2, duration=1.0, clearance=-0.5), "clearance"),
    ],
)
def test_bad_fields_are_named(make, match):
    with pytest.raises(ValidationError, match=match):
        make()


def test_windows_split_at_constraints_except_inside_sequences():
    """Figure 3 of paper 004: boundaries at 1, 5, 7, 10, 13; frame 3 lies inside a sequence."""
    constraints = [point(0, t, [t, 0]) for t in (0.1, 0.3, 0.5)]
    constraints += [point(1, t, [t, 1]) for t in (0.5, 0.7)]
    constraints += [ComConstraint(time=1.0, position=[1, 1], velocity=[1, 0])]
    constraints += [ShapeConstraint(time=1.3, shape=Polygon(vertices=[[0, 0], [1, 0], [0, 1]]), velocity=[1, 0])]
    problem = Problem(n_agents=3, duration=1.3, constraints=constraints)
    assert windows(problem) == [(0, 1), (1, 5), (5, 7), (7, 10), (10, 13)]


def test_an_unconstrained_problem_is_one_window():
    assert windows(Problem(n_agents=3, duration=2.0)) == [(0, 20)]
