"""Where a solve meets each center-of-mass constraint: its aim.

A COM constraint is a Gaussian term of the objective (standard deviation ``Problem.sigma_com``,
paper 004 section 3.4.1), and a solution meets it when its group's center lies within 3
sigma_com. Met at the exact positions, a track of COM constraints makes the group travel the
spline through them at the speed and with the turns they imply, and a model pays for every frame
the group is driven faster or harder than it moves by itself. So ``solve`` builds its initial
trajectories (and refines and regenerates them) with each COM constraint of a track moved to its
aim: the point within AIM_REACH x 3 sigma_com of its position that makes the track's path ask
least, the integral over the track of

    |path acceleration|^2 + (how far |path velocity| lies outside the model's speeds)^2 / TAU^2

for the same interpolating spline the initial trajectories follow, where the model's speeds are
the 10th to 90th percentile of its agents' speeds unconstrained. A straight path within them
stays where it is: on a straight 10 s track, aiming a group at 0.95 where the model's agents
cruise at 0.93-1.07 made the initial trajectories' impulses 1.8x larger for one seed in four (and
0.75x for another): the speed rule is stiff, and a flock's own speed wanders that much. A
velocity ``Problem`` inferred from the path through the positions is inferred again from the path
through the aims (placed at the old one, 1.39 m/s where its aimed path runs at 1.16,
obstacle-squeeze's group spent its first seconds slowing down). The sampler still scores every
COM against its own position (the objective's term), and the best sample is one within 3
sigma_com of it.
"""

from __future__ import annotations

import attrs
import numpy as np
from scipy.optimize import minimize

from .problem import ComConstraint, Problem, track_path

__all__ = ["com_aims", "PathCost"]

# How far an aim may lie from its constraint, as a share of the 3 sigma_com a solution may miss it
# by: the rest is left to the sampler, whose COM moves are kept only by the objective.
AIM_REACH = 0.9
# Seconds that turn a speed error into an acceleration in the path's cost: a path 0.1 length units
# per second too fast for the whole of a track costs as much as accelerating at 0.1 per second
# squared throughout (our choice: it weighs the two alike for a model whose groups respond
# within about a second).
TAU = 1.0
_SAMPLES_PER_SECOND = 50  # quadrature of the path's cost


def com_aims(problem: Problem, speeds: tuple[float, float]) -> Problem:
    """`problem` with the COM constraints of each track of two or more moved to their aims (see
    the module docstring), for a model whose agents move at `speeds` (lowest, highest) length units
    per second unconstrained; every other constraint as it is."""
    reach = AIM_REACH * 3 * problem.sigma_com
    moved = {}
    for track in problem.tracks:
        if isinstance(track[0], ComConstraint) and len(track) >= 2:
            times, positions = [c.time for c in track], np.array([c.position for c in track])
            aims = _aims(times, positions, speeds, reach)
            # a velocity the problem inferred from the path through the positions is inferred again
            # from the path through the aims
            inferred, aimed = (track_path(times, knots).derivative() for knots in (positions, aims))
            for c, aim in zip(track, aims):
                was_inferred = np.allclose(c.velocity, inferred(c.time), rtol=1e-9, atol=1e-12)
                moved[id(c)] = attrs.evolve(c, position=aim, velocity=aimed(c.time) if was_inferred else c.velocity)
    if not moved:
        return problem
    return attrs.evolve(problem, constraints=[moved.get(id(c), c) for c in problem.constraints])


def _aims(times, positions: np.ndarray, speeds, reach: float) -> np.ndarray:
    """(K, D) aims of one track: its `positions` (at `times`) moved by at most `reach` each to
    lower the path's cost (``PathCost``)."""
    count, dims = positions.shape
    cost = PathCost(times, speeds)

    def shifted(flat):
        value, gradient = cost(positions + flat.reshape(count, dims))
        return value, gradient.ravel()

    def inside(flat):  # >= 0: every knot within reach of its constraint
        return reach**2 - np.sum(flat.reshape(count, dims) ** 2, axis=1)

    def inside_jacobian(flat):
        rows = np.zeros((count, count, dims))
        rows[np.arange(count), np.arange(count)] = -2 * flat.reshape(count, dims)
        return rows.reshape(count, count * dims)

    found = minimize(
        shifted,
        np.zeros(count * dims),
        jac=True,
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": inside, "jac": inside_jacobian}],
    )
    shift = found.x.reshape(count, dims)
    # SLSQP may end a hair outside: scale each knot back within reach, and never worse than no aim
    norms = np.linalg.norm(shift, axis=1, keepdims=True)
    shift *= np.minimum(1.0, reach / np.maximum(norms, 1e-300))
    if cost(positions + shift)[0] > cost(positions)[0]:
        shift[...] = 0.0
    return positions + shift


class PathCost:
    """The cost of the path through knots at `times` (``flockkit.constrained.track_path``): the
    integral of |acceleration|^2 + (speed outside `speeds`)^2 / TAU^2. The spline is
    linear in its knots, so velocity and acceleration at the quadrature samples are matrices
    (samples x knots) times the knots."""

    def __init__(self, times, speeds):
        times = np.asarray(times, dtype=float)
        count = len(times)
        basis = track_path(times, np.eye(count))
        span = times[-1] - times[0]
        samples = np.linspace(times[0], times[-1], max(2, int(np.ceil(span * _SAMPLES_PER_SECOND)) + 1))
        self.weight = span / len(samples)
        self.velocity = basis.derivative(1)(samples)
        self.acceleration = basis.derivative(2)(samples) if basis.k >= 2 else np.zeros_like(self.velocity)
        self.speeds = speeds

    def __call__(self, knots) -> tuple[float, np.ndarray]:
        """(cost, its gradient with respect to the knots (K, D))."""
        v, a = self.velocity @ knots, self.acceleration @ knots
        norms = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        error = np.maximum(norms - self.speeds[1], 0.0) + np.minimum(norms - self.speeds[0], 0.0)
        value = self.weight * (np.sum(a**2) + np.sum(error**2) / TAU**2)
        along = self.velocity.T @ ((error / norms)[:, None] * v)
        return float(value), 2 * self.weight * (self.acceleration.T @ a + along / TAU**2)
