import numpy as np
import pytest

import flockkit
from flockkit import ComConstraint, PointConstraint, Polygon, Problem, ShapeConstraint
from flockkit.errors import ValidationError
from flockkit.solve import windows


def point(agent, time, position, velocity=None):
    return PointConstraint(agent=agent, time=time, position=position, velocity=velocity)


def test_frames_follow_round_time_over_dt():
    problem = Problem(n_agents=3, dt=0.1, duration=2.04)
    assert problem.n_frames == 21 and problem.frame(0.96) == 10


def test_velocities_come_from_the_spline_through_a_sequence():
    # positions on x = t^2 (a quadratic, which the cubic spline through four points reproduces)
    track = [point(0, t, [t**2, 1.0]) for t in (0.0, 1.0, 2.0, 3.0)]
    problem = Problem(n_agents=2, duration=3.0, constraints=track)
    for given, filled in zip(track, problem.constraints):
        np.testing.assert_allclose(filled.velocity, [2 * given.time, 0.0], atol=1e-9)


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
