"""Constrained animation (paper 004): windows, initial trajectories, objective and sampler."""

from .aims import com_aims
from .initial import initial_trajectories, regenerate
from .refine import refine
from .sampler import Proposal, ProposalContext, Solution, Trace, residuals, solve
from .scenario import load_scenario
from .windows import windows

__all__ = [
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
