"""Constrained animation (paper 004): windows, initial trajectories, objective and sampler."""

from .windows import windows

__all__ = ["windows"]
