"""Pictures of animated meshes: a frame, or an animation, coloured by part."""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError
from ..validate import integer
from ._figures import (
    fit_view,
    movie_path,
    picture_path,
    pyplot,
    save,
    save_animation,
    scene_figure,
    timeline,
    unit_name,
)


def _mesh_view(mesh, axes):
    """(horizontal, vertical, depth) axis indices: y up (glTF's and OBJ's convention) and, across,
    whichever of x and z the mesh spans more over its animation, unless `axes` names the pair."""
    if axes is None:
        span = np.ptp(mesh.motion.positions.reshape(-1, 3), axis=0)
        axes = (2 if span[2] > span[0] else 0, 1)
    horizontal, vertical = (integer(a, "mesh view axis", minimum=0) for a in axes)
    if len({horizontal, vertical}) != 2 or max(horizontal, vertical) > 2:
        raise ValidationError(f"mesh view axes must be two different axes of 0, 1, 2; got {axes!r}")
    return horizontal, vertical, 3 - horizontal - vertical


def _mesh_drawing(mesh, segmentation, axes, size, *, title: str):
    """A figure showing `mesh`'s faces (coloured by part), and a function drawing frame t."""
    from matplotlib.collections import PolyCollection

    from ..mesh import AnimatedMesh

    if not isinstance(mesh, AnimatedMesh):
        raise ValidationError(f"drawing a mesh needs a flockkit.AnimatedMesh; got {type(mesh).__name__}")
    if segmentation is not None:
        segmentation.check_fits(mesh.motion, "the mesh")
    plt = pyplot()
    horizontal, vertical, depth = _mesh_view(mesh, axes)
    flat = mesh.motion.positions[..., [horizontal, vertical]]
    low, high = flat.reshape(-1, 2).min(axis=0), flat.reshape(-1, 2).max(axis=0)
    figure, ax = scene_figure(plt, low, high, size, keyed=segmentation is not None)
    fit_view(ax, low, high, names=("xyz"[horizontal], "xyz"[vertical]), unit=unit_name(mesh.meters_per_unit))
    palette = plt.get_cmap("tab10" if segmentation is None or segmentation.n_parts <= 10 else "tab20")
    labels = np.zeros(mesh.motion.n_agents, dtype=int) if segmentation is None else segmentation.labels
    face_part = labels[mesh.faces[:, 0]]
    colors = np.array([palette(k % palette.N) for k in face_part]) if segmentation is not None else None
    faces = PolyCollection([], edgecolors=(0, 0, 0, 0.35), linewidths=0.3)
    ax.add_collection(faces)
    ax.set_title(title)
    if segmentation is not None:
        from matplotlib.patches import Patch

        entries = [Patch(color=palette(k % palette.N), label=f"part {k} ({len(p)} points)")
                   for k, p in enumerate(segmentation.parts())]  # fmt: skip
        figure.legend(handles=entries, loc="lower center", ncol=min(len(entries), 3), frameon=False, fontsize=8)

    def draw(frame):
        points = mesh.motion.positions[frame]
        order = np.argsort(points[mesh.faces, depth].mean(axis=1))  # far faces first: painter's order
        faces.set_verts(points[mesh.faces[order]][..., [horizontal, vertical]])
        faces.set_facecolor(colors[order] if colors is not None else (0.75, 0.78, 0.85, 1.0))
        return [faces]

    return figure, ax, draw


def plot_mesh(mesh, path=None, *, frame: int = 0, segmentation=None, axes=None, size=None):
    """One frame of an animated mesh (`flockkit.AnimatedMesh`): its faces seen from the side
    (y up; `axes` picks another pair), far faces first, coloured by part when a `segmentation` is
    given (with a legend). Returns the Figure; writes it to `path` if given."""
    if path is not None:
        path = picture_path(path)
    frame = integer(frame, "plot_mesh: frame", minimum=0)
    figure, ax, draw = _mesh_drawing(mesh, segmentation, axes, size, title="")
    if frame >= mesh.motion.n_frames:
        pyplot().close(figure)
        raise ValidationError(f"plot_mesh: frame {frame} is past the mesh's {mesh.motion.n_frames} frames")
    ax.set_title(f"{mesh.name}, t = {frame * mesh.motion.dt:.2f} s")
    draw(frame)
    if path is not None:
        save(figure, path)
    return figure


def animate_mesh(mesh, path, *, segmentation=None, axes=None, fps=None, size=None, progress=False):
    """An animation of a mesh, drawn as plot_mesh draws a frame, in real time (as animate)."""
    path = movie_path(path)
    frames, rate = timeline(mesh.motion.dt, mesh.motion.n_frames, fps, None, "animate_mesh")
    figure, ax, draw = _mesh_drawing(mesh, segmentation, axes, size, title=mesh.name)
    plt = pyplot()
    label = ax.set_title("")

    def frame_and_time(frame):
        label.set_text(f"{mesh.name}, t = {frame * mesh.motion.dt:.1f} s")
        return [*draw(frame), label]

    try:
        save_animation(figure, frame_and_time, frames, path, rate, progress)
    finally:
        plt.close(figure)
    return path
