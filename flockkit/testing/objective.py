"""Conformance checks for objective terms (``flockkit.interfaces.Objective``).

Each check is ``check_<property>(name, objective)`` and raises AssertionError saying what is
wrong. They score a simulated flock against a problem holding a constraint of every kind, some
met and some not, so every built-in term has something to say.
"""

from __future__ import annotations

import numpy as np

from ..constraints import Ball, ComConstraint, PointConstraint, Polygon, Problem, ShapeConstraint
from ..convenience import simulate
from ..motion import Motion
from ._expect import expect_validation_error


def _case() -> tuple[Motion, Problem]:
    motion = simulate(n_agents=8, steps=30, seed=31)
    far = Polygon(vertices=[[40.0, 40.0], [44.0, 40.0], [42.0, 44.0]])
    problem = Problem(
        n_agents=8, duration=3.0, visibility=1.0,  # a small visibility splits the flock
        constraints=[
            PointConstraint(agent=0, time=0.5, position=motion.positions[5, 0], velocity=[1.0, 0.0]),
            ComConstraint(time=1.0, position=motion.positions[10].mean(axis=0) + 0.3, velocity=[1.0, 0.0]),
            ComConstraint(agents=[1, 2], time=2.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
            ShapeConstraint(time=1.5, shape=far, velocity=[1.0, 0.0]),
            ShapeConstraint(agents=[3], time=2.5, shape=Ball(center=motion.positions[25, 3], radius=1.0), velocity=[1.0, 0.0]),
        ],
    )
    return motion, problem


def check_log_terms_per_frame(name, objective):
    """log_terms gives one float per frame, finite or -inf, never NaN or +inf."""
    motion, problem = _case()
    terms = np.asarray(objective.log_terms(motion, problem))
    assert terms.shape == (motion.n_frames,), f"{name}.log_terms returned shape {terms.shape}; expected ({motion.n_frames},)"
    assert not np.isnan(terms).any() and not (terms == np.inf).any(), f"{name}.log_terms holds NaN or +inf"


def check_window_is_a_slice(name, objective):
    """A window [start, stop) equals that slice of the full evaluation."""
    motion, problem = _case()
    full = np.asarray(objective.log_terms(motion, problem))
    for start, stop in ((0, 31), (10, 11), (9, 26), (30, 31), (12, 12)):
        part = np.asarray(objective.log_terms(motion, problem, start, stop))
        assert np.allclose(part, full[start:stop], rtol=1e-12, atol=1e-12, equal_nan=False), (
            f"{name}.log_terms(start={start}, stop={stop}) differs from the slice of the full evaluation"
        )


def check_inputs_unchanged(name, objective):
    """log_terms leaves the motion as it was."""
    motion, problem = _case()
    before = motion.positions.copy()
    objective.log_terms(motion, problem)
    assert np.array_equal(before, motion.positions), f"{name}.log_terms changed the motion"


def check_rejects_bad_window(name, objective):
    """A window outside the motion, or a motion of the wrong size, raises ValidationError."""
    motion, problem = _case()
    expect_validation_error(lambda: objective.log_terms(motion, problem, 5, 40), f"{name}.log_terms(start=5, stop=40)")
    expect_validation_error(lambda: objective.log_terms(motion, problem, 7, 3), f"{name}.log_terms(start=7, stop=3)")
    small = Motion(positions=motion.positions[:, :5], dt=motion.dt)
    expect_validation_error(lambda: objective.log_terms(small, problem), f"{name}.log_terms on 5 agents for an 8-agent problem")


CHECKS = (check_log_terms_per_frame, check_window_is_a_slice, check_inputs_unchanged, check_rejects_bad_window)
