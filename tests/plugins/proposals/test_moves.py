import numpy as np
import pytest
from flockkit_proposals.moves import _add_bump, _decompose, _recompose
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit import PointConstraint, Problem
from flockkit.constrained import ProposalContext, initial_trajectories, windows
from flockkit.constrained.sampler import pinned_frames


def context_for(problem, motion):
    behavior = flockkit.get("behavior", "boids")
    return ProposalContext(
        problem=problem,
        behavior=behavior,
        windows=tuple(windows(problem)),
        scores=np.zeros(motion.n_frames),
        pinned=pinned_frames(problem),
    )


@settings(max_examples=30, deadline=None)
@given(st.integers(3, 40), st.sampled_from([2, 3]), st.integers(0, 2**31))
def test_multiresolution_coordinates_recompose_exactly(count, dims, seed):
    points = np.cumsum(np.random.default_rng(seed).normal(size=(count, dims)), axis=0)
    np.testing.assert_allclose(_recompose(points[[0, -1]], _decompose(points), count), points, atol=1e-9)


def test_a_bump_keeps_the_ends_and_has_the_asked_height_on_a_straight_line():
    line = np.column_stack([np.linspace(0, 4, 9), np.zeros(9)])
    bumped = _add_bump(line, 0.1, np.random.default_rng(0))
    np.testing.assert_array_equal(bumped[[0, -1]], line[[0, -1]])
    # d = 16 s (x^2 - 2x^3 + x^4) peaks at s in the middle; coefficients scale with the length 4
    assert bumped[4, 1] == pytest.approx(0.1 * 4)
    assert np.all(bumped[1:-1, 1] > 0)


def retimings(problem, motion, seed, tries):
    """(agent, proposal) of each of `tries` velocity proposals that is not None."""
    context, rng = context_for(problem, motion), np.random.default_rng(seed)
    move = flockkit.get("proposal", "velocity")
    proposals = (move.propose(motion, context, rng) for _ in range(tries))
    return [(p.agents[0], p) for p in proposals if p is not None]


def test_retiming_keeps_the_path_and_the_distance():
    """Re-timed points lie on the cubic spline through the old samples (by arc length), between
    the segment's fixed ends, in order."""
    from scipy.interpolate import CubicSpline
    from scipy.optimize import minimize_scalar

    motion = flockkit.simulate(n_agents=5, steps=40, seed=2)
    retimed = retimings(Problem(n_agents=5, duration=4.0), motion, 1, 20)
    for agent, proposal in retimed:
        old, new = motion.positions[:, agent], proposal.motion.positions[:, agent]
        first, last = proposal.start - 1, proposal.stop
        np.testing.assert_array_equal(new[[first, last]], old[[first, last]])
        samples = old[first : last + 1]
        travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(samples, axis=0), axis=1))])
        path = CubicSpline(travelled, samples)
        grid = np.linspace(0.0, travelled[-1], 2001)
        where = []
        for point in new[first + 1 : last]:
            nearest = grid[np.argmin(np.linalg.norm(path(grid) - point, axis=1))]
            step = grid[1] - grid[0]
            fit = minimize_scalar(lambda s, f=path, p=point: np.linalg.norm(f(s) - p), method="bounded",
                                  bounds=(nearest - step, nearest + step), options={"xatol": 1e-12})  # fmt: skip
            assert fit.fun < 1e-7
            where.append(fit.x)
        assert np.all(np.diff(where) > 0)  # no agent goes back
    assert len(retimed) >= 5


def test_retiming_a_circle_keeps_its_points_on_it():
    """On the chords between samples, a re-timed point of a circle sampled every 0.1 rad would lie
    up to 1.2e-3 inside it, which boids reads as wander impulses of about its own size (0.125);
    on the spline through the samples it stays within 1e-5."""
    angles = np.arange(41) * 0.1
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    positions = np.stack([circle + [3.0 * k, 0.0] for k in range(3)], axis=1)
    motion = flockkit.Motion(positions=positions, dt=0.1)
    moved = 0.0
    for agent, proposal in retimings(Problem(n_agents=3, duration=4.0), motion, 3, 30):
        new = proposal.motion.positions[:, agent] - [3.0 * agent, 0.0]
        np.testing.assert_allclose(np.linalg.norm(new, axis=1), 1.0, atol=1e-5)
        moved = max(moved, float(np.max(np.linalg.norm(proposal.motion.positions - positions, axis=-1))))
    assert moved > 1e-3  # the points did move along the circle


def test_bumps_avoid_agents_pinned_inside_their_span():
    constraints = [
        PointConstraint(agent=a, time=t, position=[t, a], velocity=[1, 0])
        for a in range(4)
        for t in np.arange(0, 3.05, 0.1)
    ]
    problem = Problem(n_agents=5, duration=3.0, constraints=constraints)
    motion = initial_trajectories(problem, flockkit.get("behavior", "boids"), np.random.default_rng(0))
    context = context_for(problem, motion)
    rng = np.random.default_rng(3)
    for _ in range(30):
        proposal = flockkit.get("proposal", "bump").propose(motion, context, rng)
        assert proposal is None or proposal.agents == (4,)


@pytest.mark.parametrize("name, params", [("bump", {"size": 0}), ("velocity", {"spread": -1.0})])
def test_bad_parameters_are_named(name, params):
    with pytest.raises(flockkit.errors.ValidationError, match=next(iter(params))):
        flockkit.get("proposal", name, **params)
