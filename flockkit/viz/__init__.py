"""Pictures and animations, one module per domain: flocks (trajectories, problems, solves),
graphs (difference matrices, motion graphs), meshes, scenes and crowds. Needs the ``viz`` extra
(matplotlib, Pillow); every file is written atomically."""

from ._figures import ANIMATION_SUFFIXES, PICTURE_SUFFIXES
from .crowds import animate_recording, plot_offsets
from .flocks import animate, plot_motion, plot_trace
from .graphs import plot_difference_matrix, plot_graph
from .meshes import animate_mesh, plot_mesh
from .scenes import animate_scene, plot_scene

__all__ = [
    "plot_motion",
    "animate",
    "plot_trace",
    "plot_mesh",
    "animate_mesh",
    "plot_difference_matrix",
    "plot_graph",
    "plot_scene",
    "animate_scene",
    "animate_recording",
    "plot_offsets",
    "PICTURE_SUFFIXES",
    "ANIMATION_SUFFIXES",
]
