"""Background scenes (paper 002): an animated object split into parts that move independently
(``Segmentation``, ``GraphLayers``: one motion graph per part, walked out of step and played
together, seams smoothed, a mesh's copies of one point welded so it never cracks:
``crack_width``), its feature arrows (``Features``), and scenes of many duplicates of a few
templates placed in a region and animated after constraints drawn as arrows.

``FlowField`` (physical-force arrows placed anywhere, each keyframed over time, combined at an
object's position with the inverse-distance weights of section 5.2) and ``SelfMovement`` (an arrow
that rides on one object and sets its speed and heading) both give, per object and output frame, a
target feature arrow (``flockkit.Features``' form: length in [0, 1], direction). ``Scene`` places
the duplicates and walks each after its targets; objects whose arrows are self-movement
(``Features.speed``) move and turn after them (``Paths``); ``SceneAnimation`` is the result.
"""

from .animation import SceneAnimation
from .features import Features, arrow_keyframes, interpolate_arrows, stride_speed
from .file import read_scene
from .flow import Arrow, FlowField, SelfMovement
from .layers import GraphLayers, LayeredWalk, crack_width, seam_stretch, synthesize_layers, walk_layers
from .movement import Paths
from .placement import Placement
from .scene import Scene
from .segmentation import Segmentation, canonical_labels, merge_rigid_parts, same_partition

__all__ = [
    "Segmentation",
    "canonical_labels",
    "merge_rigid_parts",
    "same_partition",
    "GraphLayers",
    "LayeredWalk",
    "walk_layers",
    "synthesize_layers",
    "seam_stretch",
    "crack_width",
    "Features",
    "arrow_keyframes",
    "interpolate_arrows",
    "stride_speed",
    "Paths",
    "Arrow",
    "FlowField",
    "SelfMovement",
    "Placement",
    "Scene",
    "SceneAnimation",
    "read_scene",
]
