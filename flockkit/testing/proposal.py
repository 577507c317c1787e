"""Conformance checks for proposal moves (``flockkit.interfaces.ProposalMove``).

Each check is ``check_<property>(name, move, *, behavior=None)`` and raises AssertionError saying
what is wrong. They call the move many times on the initial trajectories of a problem with point,
COM and shape constraints (in each dimension the move declares), made with the partner
`behavior` (a model stepping dt = 0.1 s; default: the built-in ``boids``, where installed), and
look at every proposal it makes. The context holds what ``solve`` holds: the point-constrained
agent-frames and the starting state (frames 0 and 1 of every agent) as `pinned`.
"""

from __future__ import annotations

import numpy as np

from ..constrained import Proposal, ProposalContext, initial_trajectories, windows
from ..constrained.problem import ComConstraint, PointConstraint, Problem, ShapeConstraint
from ..constrained.sampler import held_frames
from ..regions import Ball, Polygon
from ._expect import dims_of, needs, partner

SEED = 5077
TRIES = 40


def _problems() -> dict[int, Problem]:
    square = Polygon(vertices=[[6.0, -2.0], [10.0, -2.0], [10.0, 2.0], [6.0, 2.0]])
    planar = Problem(
        n_agents=8,
        duration=3.0,
        constraints=[
            *(PointConstraint(agent=2, time=t, position=[t * 2.0, 0.5 * t]) for t in (0.5, 1.5, 2.5)),
            ComConstraint(agents=[0, 1, 3], time=1.0, position=[2.0, 1.0], velocity=[1.0, 0.0]),
            ShapeConstraint(time=3.0, shape=square, velocity=[1.0, 0.0]),
        ],
    )
    spatial = Problem(
        n_agents=6,
        dims=3,
        duration=2.0,
        constraints=[
            PointConstraint(agent=0, time=0.0, position=[0.0, 0.0, 0.0], velocity=[1.0, 0.0, 0.0]),
            PointConstraint(agent=4, time=1.2, position=[2.0, 1.0, 0.5], velocity=[1.0, 0.0, 0.0]),
            ShapeConstraint(
                agents=[1, 2], time=2.0, shape=Ball(center=[3.0, 0.0, 0.0], radius=1.5), velocity=[1.0, 0.0, 0.0]
            ),
        ],
    )
    return {2: planar, 3: spatial}


def _cases(move, behavior):
    """(problem, initial trajectories, context) per dimension the move declares."""
    behavior = partner(behavior, "behavior", "proposal")
    found = []
    for dims in dims_of(move):
        problem = _problems()[dims]
        motion = initial_trajectories(problem, behavior, np.random.default_rng(SEED))
        scores = np.asarray(behavior.log_plausibility(motion), dtype=np.float64)
        context = ProposalContext(
            problem=problem,
            behavior=behavior,
            windows=tuple(windows(problem)),
            scores=scores,
            pinned=held_frames(problem),
        )
        found.append((problem, motion, context))
    return found


def _proposals(move, behavior, cases=None):
    """(problem, current, proposal) for each proposal made in TRIES calls per case."""
    rng = np.random.default_rng(SEED)
    for problem, motion, context in cases or _cases(move, behavior):
        for _ in range(TRIES):
            proposal = move.propose(motion, context, rng)
            if proposal is not None:
                yield problem, motion, proposal


@needs("behavior")
def check_returns_proposals(name, move, *, behavior=None):
    """propose returns a flockkit.Proposal (or None), for a motion of the current's shape, and
    proposes something at least sometimes. (A Motion's positions are finite by construction.)"""
    made = 0
    for _, current, proposal in _proposals(move, behavior):
        assert isinstance(proposal, Proposal), (
            f"{name}.propose returned {type(proposal).__name__}, not a flockkit.Proposal or None"
        )
        shape = proposal.motion.positions.shape
        assert shape == current.positions.shape, (
            f"{name} proposed a motion of shape {shape}; the current one is {current.positions.shape}"
        )
        assert proposal.motion.dt == current.dt, f"{name} changed dt"
        made += 1
    assert made, f"{name}.propose returned None every time"


@needs("behavior")
def check_keeps_point_constraints(name, move, *, behavior=None):
    """Every point-constrained agent stays exactly at its constrained position (to 1e-9)."""
    for problem, _, proposal in _proposals(move, behavior):
        for c in problem.constraints:
            if isinstance(c, PointConstraint):
                error = np.abs(proposal.motion.positions[problem.frame(c.time), c.agent] - c.position).max()
                assert error <= 1e-9, (
                    f"{name} moved agent {c.agent} {error:.3g} off its point constraint at t={c.time:g}"
                )


@needs("behavior")
def check_leaves_held_frames(name, move, *, behavior=None):
    """Every agent-frame the context pins (``context.pinned``: point constraints and the starting
    state, frames 0 and 1 of every agent, which no term scores) keeps its exact position."""
    for problem, current, proposal in _proposals(move, behavior):
        moved = np.any(proposal.motion.positions != current.positions, axis=2) & held_frames(problem)
        if moved.any():
            frame, agent = (int(v[0]) for v in np.nonzero(moved))
            raise AssertionError(
                f"{name} moved agent {agent} at frame {frame}, which the context pins"
                + (" (the starting state: a move there buys motion no term scores)" if frame < 2 else "")
            )


@needs("behavior")
def check_reports_changes(name, move, *, behavior=None):
    """Every changed value lies at frames start <= t < stop and at the reported agents."""
    for _, current, proposal in _proposals(move, behavior):
        changed = np.any(proposal.motion.positions != current.positions, axis=2)
        frames, agents = np.nonzero(changed)
        outside = (frames < proposal.start) | (frames >= proposal.stop) | ~np.isin(agents, proposal.agents)
        assert not outside.any(), (
            f"{name} changed agent {agents[outside][0]} at frame {frames[outside][0]} but reported frames "
            f"[{proposal.start}, {proposal.stop}) and agents {proposal.agents}"
        )


@needs("behavior")
def check_input_unchanged(name, move, *, behavior=None):
    """propose leaves the current motion as it was."""
    cases = _cases(move, behavior)
    before = [motion.positions.copy() for _, motion, _ in cases]
    for _ in _proposals(move, behavior, cases):
        pass
    for (_, motion, _), positions in zip(cases, before):
        assert np.array_equal(positions, motion.positions), f"{name}.propose changed the current motion"


CHECKS = (
    check_returns_proposals,
    check_keeps_point_constraints,
    check_leaves_held_frames,
    check_reports_changes,
    check_input_unchanged,
)
