"""Windows (paper 004, section 3.3, Figure 3): the intervals the initial trajectories are built in."""

from __future__ import annotations

from .problem import Problem, ShapeConstraint


def windows(problem: Problem) -> list[tuple[int, int]]:
    """Consecutive (start, stop) frame pairs covering 0 .. n_frames - 1, stop inclusive.

    Every constrained frame starts a new window, except a frame whose constraints all lie inside
    a contiguous sequence of point or COM constraints on the same agents (neither its first nor
    its last): those are met by the sequence's B-spline path within the window.
    """
    last = problem.n_frames - 1
    boundaries = {0, last}
    inner = set()
    for track in problem.tracks:
        inner.update(id(c) for c in track[1:-1])
    for constraint in problem.constraints:
        if isinstance(constraint, ShapeConstraint) or id(constraint) not in inner:
            boundaries.add(min(problem.frame(constraint.time), last))
    ordered = sorted(boundaries)
    return list(zip(ordered[:-1], ordered[1:]))
