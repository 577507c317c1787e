"""Constrained flocks (paper 004): the constraints and the Problem that gathers them, windows,
initial trajectories, least-squares refinement, and the sampler behind ``flockkit.solve``."""

from .aims import com_aims
from .initial import initial_trajectories, regenerate
from .least_squares import refine
from .problem import ComConstraint, PointConstraint, Problem, ShapeConstraint, track_path
from .sampler import Proposal, ProposalContext, Solution, Trace, residuals, solve
from .scenario import load_scenario
from .windows import windows

__all__ = [
    "PointConstraint",
    "ComConstraint",
    "ShapeConstraint",
    "Problem",
    "track_path",
    "windows",
    "com_aims",
    "initial_trajectories",
    "regenerate",
    "refine",
    "Proposal",
    "ProposalContext",
    "Solution",
    "Trace",
    "residuals",
    "solve",
    "load_scenario",
]
