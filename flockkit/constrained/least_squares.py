"""Model-like solutions: least squares on the behavior model's residuals.

Paper 004's sampler starts from initial trajectories that meet the constraints but whose inferred
random choices (for boids, wander impulses) are hundreds of times too large, and its local moves
barely improve them. For a model that declares ``Capabilities(residuals=True)`` (log
plausibility = a constant - |r|^2 / 2 per frame), ``refine`` moves every position that no point
constraint holds so that the residuals r match targets eta: an agent-frame's own residual where
it is already one the model draws (at most LIKELY standard deviations), else one drawn from the
model itself (the residuals of a forward simulation of the same flock). That is perturb-and-MAP:
the result is a sample that looks like the model made it, not the most regular motion, which no
simulation produces. Every step keeps each constrained COM exactly where it is (the initial
trajectories meet them) and each agent near its shape's boundary at its distance from it, as
linear equalities; a step that takes an agent outside its shape is refused. What rounding leaves
is removed at the end by moving the free agents of those frames.

Each Levenberg-Marquardt step uses a sparse Jacobian made of per-agent blocks, measured by
finite differences with all agents moved together: frames 2 reach + 1 apart never share a
residual (``plausibility_reach``), so 2 reach + 1 evaluations per dimension measure every
frame's block. Moving agents together credits each agent with how its residuals follow its
neighbors' positions (cohesion, alignment, separation). A model declaring
``Capabilities(coupling=True)`` gives those derivatives (``plausibility_coupling``); they are then
put where they belong and taken off the agent's own block, so the Jacobian is exact, where the
normal equations, which then join every agent of a frame to its neighbors, are affordable to
solve (COUPLING_BUDGET; a banded Cholesky factor, see ``_step``). bench/README.md records what
each refinement gains on the example scenarios.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded
from scipy.sparse import bmat, coo_matrix, diags, tril
from scipy.sparse.csgraph import reverse_cuthill_mckee
from scipy.sparse.linalg import spsolve

from ..errors import ValidationError
from ..interfaces import capabilities
from ..motion import Motion
from .problem import ComConstraint, Problem, ShapeConstraint

__all__ = ["refine"]

LIKELY = 3.0  # residual lengths (in standard deviations) kept as their own targets
BOUNDARY = 0.05  # agents this close to their shape's boundary move along it, not across
# The model's coupling (Capabilities.coupling) joins every agent of a frame to its neighbors, so
# each step factors a band of about 4 N D (four frames of agents) over all T N D positions: about
# T N D (4 N D)^2 operations. Above this many, steps go without it: the scenarios measured in
# bench/README.md gain much from it at 5e7 (obstacle-squeeze) and little at 1.9e9 (arrows), for
# nine times the time.
COUPLING_BUDGET = 3e8
_STEP = 1e-6  # finite-difference step, in the motion's length units


def refine(
    problem: Problem,
    behavior,
    motion: Motion,
    pinned: np.ndarray,
    rng,
    *,
    iterations: int = 40,
    sample: bool = True,
    coupling: bool = True,
) -> Motion:
    """`motion` improved by least squares on `behavior`'s residuals (see the module docstring),
    every agent-frame of `pinned` (T, N) and the first two frames (the state it starts from)
    held where they are; at most `iterations` steps. With ``sample=False`` the targets are zero:
    the most regular motion the steps reach (a bound on what the model allows, not a sample).
    With ``coupling=False`` the steps leave out the model's coupling even where it is declared
    and affordable (COUPLING_BUDGET): several times cheaper, as ``solve`` ranks its starts."""
    if not capabilities(behavior).residuals:
        raise ValidationError("refine needs a behavior model declaring Capabilities(residuals=True)")
    return _Refinement(problem, behavior, motion, pinned, rng, sample, coupling).run(iterations)


class _Refinement:
    def __init__(self, problem, behavior, motion, pinned, rng, sample=True, coupling=True):
        self.problem, self.behavior, self.motion = problem, behavior, motion
        self.shape = motion.positions.shape
        t, n, d = self.shape
        held = pinned.copy()
        held[:2] = True  # the starting state: its velocity carries no impulse, so nothing would bound it
        self.free = np.repeat(~held[:, :, None], d, axis=2)
        self.index = np.full(self.shape, -1)
        self.index[self.free] = np.arange(int(self.free.sum()))
        declared = capabilities(behavior)
        self.reach = t if declared.plausibility_reach is None else declared.plausibility_reach
        self.coupled = coupling and declared.coupling and self.free.sum() * (4 * n * d) ** 2 <= COUPLING_BUDGET
        # targets: each agent-frame's own residual where it is already one the model draws, else
        # one drawn by a forward simulation of the same flock; zero without sampling
        self.targets = np.asarray(behavior.plausibility_residuals(motion)).copy()
        if not sample:
            self.targets[...] = 0.0
        else:
            simulated = np.asarray(behavior.plausibility_residuals(behavior.forward(motion.state(0), t - 1, rng)))
            unlikely = np.linalg.norm(self.targets, axis=-1) > LIKELY
            self.targets[unlikely] = simulated[unlikely]
        # each agent's residuals weighed as the objective weighs its terms (Problem.keyframed_weight)
        self.rows = np.sqrt(problem.agent_weights())
        self.coms = [(problem.frame(c.time), np.array(problem.agents_of(c)), np.asarray(c.position))
                     for c in problem.constraints if isinstance(c, ComConstraint)]  # fmt: skip
        self.shapes = [(problem.frame(c.time), np.array(problem.agents_of(c)), c.shape)
                       for c in problem.constraints if isinstance(c, ShapeConstraint)]  # fmt: skip

    def _motion(self, positions) -> Motion:
        return Motion(positions=positions, dt=self.motion.dt, channels=dict(self.motion.channels))

    def _model(self, positions) -> np.ndarray:
        residuals = np.asarray(self.behavior.plausibility_residuals(self._motion(positions))) - self.targets
        return residuals * self.rows[None, :, None]

    def _cost(self, positions) -> tuple[float, np.ndarray]:
        """Half the squared residuals; infinite where an agent has left its shape."""
        model = self._model(positions)
        for f, agents, shape in self.shapes:
            if np.any(shape.signed_distance(positions[f, agents]) > 0):
                return np.inf, model
        return 0.5 * float(np.sum(model**2)), model

    def _jacobian(self, positions, model):
        """Sparse (residuals, free values) Jacobian: per-agent blocks of the model's residuals
        (see the module docstring)."""
        t, n, d = self.shape
        k = model.shape[2]
        spacing = 2 * self.reach + 1
        rows, cols, values = [], [], []
        for color in range(min(spacing, t)):
            moved = np.arange(color, t, spacing)
            for dim in range(d):
                nudged = positions.copy()
                nudged[moved, :, dim] += np.where(self.free[moved, :, dim], _STEP, 0.0)
                change = (self._model(nudged) - model) / _STEP  # (T, N, K)
                for offset in range(-self.reach, self.reach + 1):
                    f = moved[(moved + offset >= 0) & (moved + offset < t)]
                    # each agent's rows at frame f + offset against its own column at frame f
                    row = ((f[:, None, None] + offset) * n + np.arange(n)[None, :, None]) * k + np.arange(k)
                    column = np.broadcast_to(self.index[f, :, dim][:, :, None], row.shape)
                    value = change[f + offset]
                    keep = (column >= 0) & (value != 0)
                    rows.append(row[keep])
                    cols.append(column[keep])
                    values.append(value[keep])
        if self.coupled:
            for found, extra in zip((rows, cols, values), self._coupling(positions, k)):
                found.extend(extra)
        size = (t * n * k, int(self.free.sum()))
        return coo_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=size).tocsr()

    def _coupling(self, positions, k):
        """The model's coupling (``Capabilities.coupling``) on free columns, each entry also taken
        off the row agent's own column at the same frame and dimension: the finite differences
        above moved the neighbors with the agent, crediting it with their share."""
        t, n, d = self.shape
        coupling = self.behavior.plausibility_coupling(self._motion(positions)).tocoo()
        row, column = coupling.row, coupling.col
        value = coupling.data * self.rows[(row // k) % n]
        frame, dim = column // (n * d), column % d
        own = self.index.ravel()[(frame * n + (row // k) % n) * d + dim]
        other = self.index.ravel()[column]
        keep = other >= 0
        mine = keep & (own >= 0)
        return [row[keep], row[mine]], [other[keep], own[mine]], [value[keep], -value[mine]]

    def _equalities(self, positions):
        """Linear equalities (rows over the free values, right-hand sides) that every step meets:
        each constrained COM stays where it is (the initial trajectories meet them), and each
        agent within BOUNDARY of its shape's boundary keeps its distance to it (one outside
        steps onto it), sliding along it at most."""
        d = self.shape[2]
        rows, cols, values, targets = [], [], [], []
        for f, agents, _ in self.coms:
            for dim in range(d):
                column = self.index[f, agents, dim]
                column = column[column >= 0]
                if not len(column):  # every agent of it held at that frame: it stays as it is
                    continue
                rows.append(np.full(len(column), len(targets)))
                cols.append(column)
                values.append(np.ones(len(column)))
                targets.append(0.0)
        for f, agents, shape in self.shapes:
            free = agents[self.free[f, agents, 0]]
            depth = shape.signed_distance(positions[f, free])
            near = depth > -BOUNDARY
            for agent, normal, distance in zip(free[near], shape.surface_normal(positions[f, free[near]]), depth[near]):
                rows.append(np.full(d, len(targets)))
                cols.append(self.index[f, agent])
                values.append(normal)
                targets.append(min(0.0, -distance - 1e-6))
        if not targets:
            return None
        matrix = coo_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                            shape=(len(targets), int(self.free.sum())))  # fmt: skip
        return matrix.tocsr(), np.array(targets)

    def run(self, iterations: int) -> Motion:
        positions = np.array(self.motion.positions)
        cost, model = self._cost(positions)
        damping = 1e-3
        for _ in range(iterations):
            jacobian = self._jacobian(positions, model)
            gradient = jacobian.T @ model.ravel()
            normal = (jacobian.T @ jacobian).tocsc()
            scale = normal.diagonal()
            equalities = self._equalities(positions)
            for _ in range(10):
                step = _step(normal + diags(damping * scale + 1e-12), gradient, equalities, self.coupled)
                if not np.all(np.isfinite(step)):
                    damping *= 4
                    continue
                trial = positions.copy()
                trial[self.free] += step
                trial_cost, trial_model = self._cost(trial)
                if trial_cost < cost:
                    break
                damping *= 4
            else:
                break  # no step helps: a local optimum, or a kink the steps cannot pass
            done = cost - trial_cost <= 1e-6 * cost
            positions, cost, model = trial, trial_cost, trial_model
            damping = max(damping / 3, 1e-9)
            if done:
                break
        return self._motion(self._exact(positions))

    def _exact(self, positions) -> np.ndarray:
        """Remove what the steps left of COM errors (rounding) and of agents outside their
        shapes, by moving the free agents of those frames."""
        positions = positions.copy()
        for f, agents, target in self.coms:
            free = agents[self.free[f, agents, 0]]
            if len(free):
                positions[f, free] += (target - positions[f, agents].mean(axis=0)) * len(agents) / len(free)
        for f, agents, shape in self.shapes:
            free = agents[self.free[f, agents, 0]]
            for _ in range(3):  # a step along the nearest boundary's normal; again at corners
                depth = shape.signed_distance(positions[f, free])
                out = depth > -1e-9
                if not out.any():
                    break
                inward = (depth[out] + 1e-6)[:, None] * shape.surface_normal(positions[f, free[out]])
                positions[f, free[out]] -= inward
        return positions


def _step(matrix, gradient, equalities, banded: bool) -> np.ndarray:
    """The damped Gauss-Newton step meeting the linear equalities. Without the coupling, `matrix`
    (J^T J, damped) holds one chain of frames per agent, and a sparse LU of the KKT system keeps
    it sparse. With it, every agent of a frame meets its neighbors; ordered by frame (reverse
    Cuthill-McKee) the matrix is banded, and a banded Cholesky factor solves it several times
    faster than the LU (0.8 s a solve on arrows' 50 agents), the equalities' multipliers coming
    from their Schur complement (dense, one column per equality: small where steps are coupled)."""
    if not banded:
        if equalities is None:
            return spsolve(matrix, -gradient)
        rows, targets = equalities
        system = bmat([[matrix, rows.T], [rows, None]], format="csc")
        return spsolve(system, np.concatenate([-gradient, targets]))[: matrix.shape[0]]
    order = reverse_cuthill_mckee(matrix.tocsr(), symmetric_mode=True)
    back = np.argsort(order)
    lower = tril(matrix.tocsr()[order][:, order]).tocoo()
    band = lower.row - lower.col
    packed = np.zeros((int(band.max(initial=0)) + 1, matrix.shape[0]))
    packed[band, lower.col] = lower.data
    try:
        factor = cholesky_banded(packed, lower=True)
    except np.linalg.LinAlgError:
        return np.full(matrix.shape[0], np.nan)  # not positive definite: the caller damps more

    def solve(rhs):
        return cho_solve_banded((factor, True), rhs[order])[back]

    step = solve(-gradient)
    if equalities is None:
        return step
    rows, targets = equalities
    spread = solve(rows.T.toarray())  # A^-1 E^T
    multipliers = np.linalg.lstsq(rows @ spread, rows @ step - targets, rcond=None)[0]
    return step - spread @ multipliers
