"""Background scenes (paper 002, sections 5 and 6): many duplicates of a few templates, placed in
a region and animated after constraints drawn as arrows.

``FlowField`` (physical-force arrows placed anywhere, each keyframed over time, combined at an
object's position with the inverse-distance weights of section 5.2) and ``SelfMovement`` (an arrow
that rides on one object and sets its speed and heading) both give, per object and output frame, a
target feature arrow (``flockkit.Features``' form: length in [0, 1], direction). ``Scene`` places
the duplicates and walks each after its targets; ``SceneAnimation`` is the result.
"""

from .file import read_scene
from .flow import Arrow, FlowField, SelfMovement
from .scene import Placement, Scene, SceneAnimation

__all__ = ["Arrow", "FlowField", "Placement", "Scene", "SceneAnimation", "SelfMovement", "read_scene"]
