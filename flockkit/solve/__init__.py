"""Constrained animation (paper 004): windows, initial trajectories, objective and sampler."""

from .initial import initial_trajectories, regenerate
from .refine import refine
from .sampler import Proposal, ProposalContext, Solution, Trace, residuals, solve
from .scenario import load_scenario
from .windows import windows

__all__ = [
    "windows",
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
