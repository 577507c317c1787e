"""flockkit: data-driven and constrained animation of groups of agents.

The public API. Value types (``Motion``, ``Configuration``, ``State``, regions), the plugin
lookup (``get``, ``available``, ``hookimpl``) and the convenience layer (``simulate``).
"""

from . import errors, io
from .constraints import Ball, Box, ComConstraint, PointConstraint, Polygon, Problem, ShapeConstraint
from .convenience import build_graph, random_flock, simulate, walk
from .graph import Clip, MotionGraph, Transition, Walk
from .synthesis import synthesize, synthesize_many
from .hookspecs import hookimpl
from .solve import Proposal, Solution, solve
from .motion import DEFAULT_UP, Alignment, Configuration, ConfigurationFrame, Motion, State, heading_axes
from .registry import available, get

__version__ = "0.1.0"

__all__ = [
    "Motion",
    "Configuration",
    "ConfigurationFrame",
    "heading_axes",
    "Alignment",
    "State",
    "DEFAULT_UP",
    "MotionGraph",
    "Clip",
    "Transition",
    "Walk",
    "synthesize",
    "synthesize_many",
    "Ball",
    "Box",
    "Polygon",
    "PointConstraint",
    "ComConstraint",
    "ShapeConstraint",
    "Problem",
    "get",
    "available",
    "hookimpl",
    "simulate",
    "build_graph",
    "walk",
    "solve",
    "Solution",
    "Proposal",
    "random_flock",
    "errors",
    "io",
    "__version__",
]
