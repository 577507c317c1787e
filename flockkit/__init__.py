"""flockkit: data-driven and constrained animation of groups of agents.

The public API. Value types (``Motion``, ``Configuration``, ``State``, regions), the plugin
lookup (``get``, ``resolve``, ``available``, ``hookimpl``) and declared ``Capabilities``, the
convenience layer (``simulate``, ``build_graph``, ``walk``, ``solve``), rigid motions
(``flockkit.rigid``) and the checks plugins share (``flockkit.validate``).
"""

from . import constrained, crowd, errors, graphs, io, parallel, rigid, scene, validate
from ._version import __version__
from .constrained import Proposal, Solution, solve
from .constrained.problem import ComConstraint, PointConstraint, Problem, ShapeConstraint
from .convenience import build_graph, build_layers, segment, simulate, synthesize, walk
from .crowd import Channel, Crowd, Event, Pose, SkeletalClip, Skeleton, Stream, StreamPool, UniquePool
from .graphs import Clip, MotionGraph, Transition, Walk, synthesize_many
from .hookspecs import hookimpl
from .interfaces import Capabilities, capabilities
from .mesh import AnimatedMesh, MeshSkin
from .motion import DEFAULT_UP, Alignment, Configuration, ConfigurationFrame, Motion, State, heading_axes, random_flock
from .regions import Ball, Box, Polygon, Region, fence
from .registry import available, get, resolve
from .scene import Features, GraphLayers, LayeredWalk, Scene, SceneAnimation, Segmentation

__all__ = [
    "Motion",
    "AnimatedMesh",
    "MeshSkin",
    "Features",
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
    "Region",
    "fence",
    "PointConstraint",
    "ComConstraint",
    "ShapeConstraint",
    "Problem",
    "get",
    "resolve",
    "available",
    "Capabilities",
    "capabilities",
    "hookimpl",
    "simulate",
    "build_graph",
    "segment",
    "Segmentation",
    "build_layers",
    "Scene",
    "SceneAnimation",
    "Skeleton",
    "Pose",
    "SkeletalClip",
    "Channel",
    "Event",
    "Stream",
    "StreamPool",
    "UniquePool",
    "Crowd",
    "GraphLayers",
    "LayeredWalk",
    "walk",
    "solve",
    "Solution",
    "Proposal",
    "random_flock",
    "constrained",
    "crowd",
    "errors",
    "graphs",
    "io",
    "scene",
    "parallel",
    "rigid",
    "validate",
    "__version__",
]
