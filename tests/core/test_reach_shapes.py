"""The reach check on shape constraints (flockkit.constrained.reach): three shapes holding the same
agents make a track of their centroids, whose turns are judged as a COM track's are, even where
the shapes overlap and their boxes' gap asks for no speed."""

import warnings

import numpy as np
import pytest

import flockkit
from flockkit import Box, Problem, ShapeConstraint
from flockkit.constrained.reach import IMPLAUSIBLE, IMPLAUSIBLE_TURN, _shape_legs, _turning, unconstrained
from flockkit.errors import FlockkitWarning


def _shapes(centres, size=1.5, times=(1.0, 3.0, 5.0)):
    half = size / 2
    return [ShapeConstraint(time=t, shape=Box(lower=[x - half, y - half], upper=[x + half, y + half]),
                            velocity=[1.0, 0.0]) for t, (x, y) in zip(times, centres)]  # fmt: skip


def test_shapes_that_turn_their_group_harder_than_the_model_warn_at_the_corner_and_are_still_met():
    """Boxes 2 apart, 2 s apart, doubling back: their gaps (0.5) ask for 0.25 per second, nothing
    to warn of, but their centroids' legs differ by 2 per second over 4 s: 0.5 per second squared,
    far beyond what the center of 8 boids does. The same boxes in a straight line say nothing."""
    problem = Problem(n_agents=8, duration=5.0, constraints=_shapes([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]]))
    assert max(gap for *_, gap in _shape_legs(problem)) / 2.0 < IMPLAUSIBLE * 0.9  # no speed to judge
    free = unconstrained(problem, flockkit.get("behavior", "boids"), 1)
    assert 0 < IMPLAUSIBLE_TURN * np.percentile(_turning(free, range(8), (20, 20)), 99) < 0.5
    pattern = (r"constraint 1 \(ShapeConstraint at t=3\) turns its 8 agents' center at 0.5 length units per second "
               r"squared on average between t=1 and t=5")  # fmt: skip
    with pytest.warns(FlockkitWarning, match=pattern) as caught:
        solution = flockkit.solve(problem, iterations=0, refine=0, seed=1)
    assert len(caught) == 1
    assert solution.residuals == (0.0, 0.0, 0.0)
    straight = Problem(n_agents=8, duration=5.0, constraints=_shapes([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flockkit.solve(straight, iterations=0, refine=0, seed=1)


def test_a_shape_track_is_judged_per_group_of_agents():
    """Two groups, each held by shapes at every time: one group's shapes double back and warn, the
    other's run straight; a pair of shapes alone is no turn."""
    first = [ShapeConstraint(agents=(0, 1, 2, 3), time=c.time, shape=c.shape, velocity=c.velocity)
             for c in _shapes([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]])]  # fmt: skip
    second = [ShapeConstraint(agents=(4, 5, 6, 7), time=c.time, shape=c.shape, velocity=c.velocity)
              for c in _shapes([[0.0, 5.0], [2.0, 5.0], [4.0, 5.0]])]  # fmt: skip
    problem = Problem(n_agents=8, duration=5.0, constraints=first + second)
    with pytest.warns(FlockkitWarning) as caught:
        flockkit.solve(problem, iterations=0, refine=0, seed=1)
    assert [str(w.message).split(" turns ")[0] for w in caught] == ["constraint 1 (ShapeConstraint at t=3)"]
    pair = Problem(n_agents=8, duration=5.0, constraints=_shapes([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]])[:2])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flockkit.solve(pair, iterations=0, refine=0, seed=1)


def test_paper_arrows_turning_with_the_flock_warn_and_the_shipped_ones_do_not():
    """Paper 004's arrows as first shipped (12.5 m long, pointing right, up and left 4 s apart,
    each where the last pointed) overlap, so their boxes ask for no speed, but they turn their 50
    agents' center at 0.19 per second squared: the middle one warns. The shipped arrows ride on
    the flock's straight path and say nothing (tests/plugins/proposals/test_examples.py)."""
    arrows = [
        [[0.0, -1.25], [7.5, -1.25], [7.5, -3.75], [12.5, 0.0], [7.5, 3.75], [7.5, 1.25], [0.0, 1.25]],
        [[11.25, -2.0], [11.25, 5.5], [13.75, 5.5], [10.0, 10.5], [6.25, 5.5], [8.75, 5.5], [8.75, -2.0]],
        [[14.0, 11.25], [6.5, 11.25], [6.5, 13.75], [1.5, 10.0], [6.5, 6.25], [6.5, 8.75], [14.0, 8.75]],
    ]
    headings = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]
    shapes = [ShapeConstraint(time=4.0 * (k + 1), shape=flockkit.Polygon(vertices=arrow), velocity=heading)
              for k, (arrow, heading) in enumerate(zip(arrows, headings))]  # fmt: skip
    problem = Problem(n_agents=50, duration=12.0, constraints=shapes)
    assert all(gap == 0 for *_, gap in _shape_legs(problem))
    pattern = r"constraint 1 \(ShapeConstraint at t=8\) turns its 50 agents' center at 0.19\d* length units"
    with pytest.warns(FlockkitWarning, match=pattern):
        flockkit.solve(problem, iterations=0, refine=0, starts=1, seed=1)
