"""Conformance checks for objective terms (``flockkit.interfaces.Objective``).

Each check is ``check_<property>(name, objective)`` and raises AssertionError saying what is
wrong. They score the kit's recording against a problem holding a constraint of every kind, some
met and some not, so every built-in term has something to say, in each declared dimension.
"""

from __future__ import annotations

import numpy as np

from ..constrained.problem import ComConstraint, PointConstraint, Problem, ShapeConstraint
from ..motion import Motion
from ..regions import Ball, Box, Polygon
from ._expect import dims_of, expect_validation_error, on_input
from .inputs import recording


def _case(dims: int) -> tuple[Motion, Problem]:
    motion = recording(n_agents=8, seconds=3.0, dims=dims, seed=31)
    heading = np.eye(dims)[0]
    if dims == 2:
        far = Polygon(vertices=[[40.0, 40.0], [44.0, 40.0], [42.0, 44.0]])
    else:
        far = Box(lower=[40.0, 40.0, 40.0], upper=[44.0, 44.0, 44.0])
    problem = Problem(
        n_agents=8,
        dims=dims,
        duration=3.0,
        visibility=1.0,  # a small visibility splits the group
        constraints=[
            PointConstraint(agent=0, time=0.5, position=motion.positions[5, 0], velocity=heading),
            ComConstraint(time=1.0, position=motion.positions[10].mean(axis=0) + 0.3, velocity=heading),
            ComConstraint(agents=[1, 2], time=2.0, position=np.zeros(dims), velocity=heading),
            ShapeConstraint(time=1.5, shape=far, velocity=heading),
            ShapeConstraint(
                agents=[3], time=2.5, shape=Ball(center=motion.positions[25, 3], radius=1.0), velocity=heading
            ),
        ],
    )
    return motion, problem


def _cases(name, objective):
    """(motion, problem, context) per declared dimension; the context names it in failures."""
    for dims in dims_of(objective):
        yield *_case(dims), on_input(name, objective, dims, "the kit's case")


def check_log_terms_per_frame(name, objective):
    """log_terms gives one float per frame, finite or -inf, never NaN or +inf."""
    for motion, problem, context in _cases(name, objective):
        with context:
            terms = np.asarray(objective.log_terms(motion, problem))
            assert terms.shape == (motion.n_frames,), (
                f"{name}.log_terms returned shape {terms.shape}; expected ({motion.n_frames},)"
            )
            assert not np.isnan(terms).any() and not (terms == np.inf).any(), f"{name}.log_terms holds NaN or +inf"


def check_window_is_a_slice(name, objective):
    """A window [start, stop) equals that slice of the full evaluation."""
    for motion, problem, context in _cases(name, objective):
        with context:
            full = np.asarray(objective.log_terms(motion, problem))
            for start, stop in ((0, 31), (10, 11), (9, 26), (30, 31), (12, 12)):
                part = np.asarray(objective.log_terms(motion, problem, start, stop))
                assert np.allclose(part, full[start:stop], rtol=1e-12, atol=1e-12, equal_nan=False), (
                    f"{name}.log_terms(start={start}, stop={stop}) differs from the slice of the full evaluation"
                )


def check_inputs_unchanged(name, objective):
    """log_terms leaves the motion as it was."""
    for motion, problem, _ in _cases(name, objective):
        before = motion.positions.copy()
        objective.log_terms(motion, problem)
        assert np.array_equal(before, motion.positions), f"{name}.log_terms changed the motion"


def check_rejects_bad_window(name, objective):
    """A window outside the motion, or a motion of the wrong size, raises ValidationError."""
    motion, problem = _case(dims_of(objective)[0])
    expect_validation_error(lambda: objective.log_terms(motion, problem, 5, 40), f"{name}.log_terms(start=5, stop=40)")
    expect_validation_error(lambda: objective.log_terms(motion, problem, 7, 3), f"{name}.log_terms(start=7, stop=3)")
    small = Motion(positions=motion.positions[:, :5], dt=motion.dt)
    expect_validation_error(
        lambda: objective.log_terms(small, problem), f"{name}.log_terms on 5 agents for an 8-agent problem"
    )


CHECKS = (check_log_terms_per_frame, check_window_is_a_slice, check_inputs_unchanged, check_rejects_bad_window)
