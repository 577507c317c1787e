"""Pictures of flockkit values (extra ``viz``: matplotlib and pillow)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .constraints import Ball, Box, Polygon
from .errors import MissingDependencyError, ValidationError
from .motion import Motion

__all__ = ["plot_motion", "PICTURE_SUFFIXES"]

PICTURE_SUFFIXES = (".png", ".pdf", ".svg")


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("pictures need matplotlib: pip install 'flockkit[viz]'") from None
    return plt


def _check_picture_path(path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in PICTURE_SUFFIXES:
        raise ValidationError(f"picture path {path}: unknown extension {path.suffix!r}; expected one of {', '.join(PICTURE_SUFFIXES)}")
    return path


def _draw_region(ax, region, **style):
    import matplotlib.patches as patches

    if isinstance(region, Ball):
        ax.add_patch(patches.Circle(region.center[:2], region.radius, **style))
    elif isinstance(region, Box):
        size = region.upper[:2] - region.lower[:2]
        ax.add_patch(patches.Rectangle(region.lower[:2], size[0], size[1], **style))
    elif isinstance(region, Polygon):
        ax.add_patch(patches.Polygon(region.vertices, closed=True, **style))


def plot_motion(motion: Motion, path=None, *, obstacles=(), ax=None, title=None):
    """Draw every agent's trajectory (x-y plane), its start (dot) and end (arrow along the last
    velocity), and any obstacles. Returns the matplotlib Figure; writes it to `path` if given
    (.png, .pdf or .svg; atomically)."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"plot_motion needs a flockkit.Motion; got {type(motion).__name__}")
    if path is not None:
        path = _check_picture_path(path)
    plt = _pyplot()
    figure = ax.figure if ax is not None else plt.figure(figsize=(7, 7))
    ax = ax or figure.add_subplot()
    xy = motion.positions[..., :2]
    colors = plt.get_cmap("viridis")(np.linspace(0, 1, motion.n_agents))
    for agent in range(motion.n_agents):
        ax.plot(xy[:, agent, 0], xy[:, agent, 1], color=colors[agent], linewidth=0.8, alpha=0.8)
    ax.scatter(xy[0, :, 0], xy[0, :, 1], s=8, color="0.4", label="start", zorder=3)
    travel = 0.5 * motion.velocities()[-1, :, :2]  # arrows show half a second of travel
    ax.quiver(xy[-1, :, 0], xy[-1, :, 1], travel[:, 0], travel[:, 1], color="black", angles="xy",
              scale_units="xy", scale=1.0, width=0.004, zorder=4, label="end")
    for obstacle in obstacles:
        _draw_region(ax, obstacle, facecolor="0.75", edgecolor="0.3")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(title or f"{motion.n_agents} agents, {motion.duration:g} s")
    ax.legend(loc="upper right")
    if path is not None:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent if str(path.parent) else ".")
        os.close(fd)
        try:
            figure.savefig(tmp, dpi=120, bbox_inches="tight")
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return figure
