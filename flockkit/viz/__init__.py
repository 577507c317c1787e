"""Pictures and animations, one module per domain: flocks (trajectories, problems, solves),
graphs (difference matrices, motion graphs), meshes, scenes and crowds; and renders of any of
them through Blender (``render_blender``, in a Python that has bpy). Needs the ``viz`` extra
(matplotlib, Pillow); every file is written atomically."""

from ._figures import ANIMATION_SUFFIXES, PICTURE_SUFFIXES
from .crowds import animate_recording, plot_offsets
from .flocks import animate, plot_motion, plot_trace
from .graphs import plot_difference_matrix, plot_graph
from .meshes import animate_mesh, plot_mesh
from .render import render_blender
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
    "render_blender",
    "PICTURE_SUFFIXES",
    "ANIMATION_SUFFIXES",
]
