"""Pictures of flocks: a motion's trajectories with its problem's constraints, obstacles and
regions, its animation, and a constrained solve's trace."""

from __future__ import annotations

import numpy as np

from ..constrained.problem import ComConstraint, PointConstraint, ShapeConstraint
from ..errors import ValidationError
from ..motion import Motion
from ..validate import number
from ._figures import (
    ARROW,
    draw_region,
    fit_view,
    movie_path,
    picture_path,
    pyplot,
    save,
    save_animation,
    scene_figure,
    timeline,
)
from ._figures import unit as normalized

_PINNED, _FREE = "tab:red", "tab:blue"

_REGION_COLORS = ("tab:green", "tab:olive", "tab:cyan", "tab:brown")


def plot_motion(motion: Motion, path=None, *, problem=None, obstacles=(), regions=(), ax=None, title=None, unit="m"):
    """Draw every agent's trajectory (x-y plane), its start (dot) and end (arrow along its last
    heading, ARROW of the scene's extent long), obstacles (grey), `regions` (outlined; a
    sequence, or a mapping from legend label to region) and, with a `problem`, its
    constraints: point targets (crosses), COM targets (stars) and shapes (dashed),
    and its point-constrained agents in red, the others in blue. The legend names every kind of
    mark; the figure takes the scene's proportions; the axes say `unit`, the unit of the
    positions (flockkit's metres by default; "px" for a capture in a video's pixels). Returns the
    matplotlib Figure; writes it to `path` if given (.png, .pdf or .svg; atomically)."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"plot_motion needs a flockkit.Motion; got {type(motion).__name__}")
    if path is not None:
        path = picture_path(path)
    regions = _named(regions)
    plt = pyplot()
    xy = motion.positions[..., :2]
    low, high = _scene_bounds(xy, problem, obstacles, regions)
    given = ax is not None
    figure, ax = (ax.figure, ax) if given else scene_figure(plt, low, high, None, keyed=True, longer=800)
    colors = _roles(motion.n_agents, problem)
    pinned = [c == _PINNED for c in colors]
    for agent in np.argsort(pinned, kind="stable"):  # the constrained agents on top
        ax.plot(xy[:, agent, 0], xy[:, agent, 1], color=colors[agent], linewidth=1.6 if pinned[agent] else 0.8,
                alpha=0.9 if pinned[agent] else 0.6)  # fmt: skip
    ax.scatter(xy[0, :, 0], xy[0, :, 1], s=10, color="0.3", zorder=3)
    extent = fit_view(ax, low, high, unit=unit)
    heading = normalized(motion.velocities()[-1, :, :2]) * ARROW * extent
    ax.quiver(xy[-1, :, 0], xy[-1, :, 1], heading[:, 0], heading[:, 1], color=colors, angles="xy",
              scale_units="xy", scale=1.0, width=0.004, zorder=4)  # fmt: skip
    _draw_scene(ax, problem, obstacles, regions)
    ax.set_title(title or f"{motion.n_agents} agents, {motion.duration:g} s")
    _legend(ax, problem, obstacles, regions, inside=given)
    if path is not None:
        save(figure, path)
    return figure


def _named(regions) -> dict:
    """`regions` (a sequence of regions, or a mapping from legend label to region) as a mapping."""
    from ..regions import Region

    named = dict(regions) if isinstance(regions, dict) else {f"region {i + 1}": r for i, r in enumerate(regions)}
    if len(named) == 1 and not isinstance(regions, dict):
        named = {"region": next(iter(named.values()))}
    for label, region in named.items():
        if not isinstance(region, Region):
            raise ValidationError(f"regions: {label!r} must be a flockkit region; got {type(region).__name__}")
    return named


def _scene_bounds(xy, problem, obstacles, regions):
    """The (lower, upper) x-y corners of everything drawn: paths, obstacles, regions, targets."""
    points = [xy.reshape(-1, 2)]
    obstacles = tuple(obstacles) + (tuple(problem.obstacles) if problem is not None else ())
    points += [shape.outline()[:, :2] for shape in (*obstacles, *regions.values())]
    if problem is not None:
        for c in problem.constraints:
            if isinstance(c, (PointConstraint, ComConstraint)):
                points.append(np.asarray(c.position)[None, :2])
            elif isinstance(c, ShapeConstraint):
                points.append(c.shape.outline()[:, :2])
    points = np.concatenate(points)
    return points.min(axis=0), points.max(axis=0)


def _draw_scene(ax, problem, obstacles, regions):
    """Obstacles, regions and a problem's constraints, in the x-y plane."""
    obstacles = tuple(obstacles) + (tuple(problem.obstacles) if problem is not None else ())
    for obstacle in obstacles:
        draw_region(ax, obstacle, facecolor="0.75", edgecolor="0.3")
    for region, color in zip(regions.values(), _REGION_COLORS * len(regions)):
        draw_region(ax, region, fill=False, edgecolor=color, linewidth=1.5)
    if problem is None:
        return
    for c in problem.constraints:
        if isinstance(c, PointConstraint):
            ax.scatter(*c.position[:2], marker="x", s=70, linewidths=2, color="darkred", zorder=5)
        elif isinstance(c, ComConstraint):
            ax.scatter(*c.position[:2], marker="*", s=140, color="tab:orange", edgecolors="black", zorder=5)
        elif isinstance(c, ShapeConstraint):
            draw_region(ax, c.shape, fill=False, edgecolor="tab:purple", linestyle="--", linewidth=1.2)


def _legend(ax, problem, obstacles, regions, *, inside: bool = False, ends: bool = True) -> None:
    """A legend with one entry for every kind of mark drawn (`ends`: start dots and end arrows),
    at the bottom of the figure (where scene_figure left room) or `inside` the axes."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    kinds = {type(c) for c in problem.constraints} if problem is not None else set()
    pinned = sorted({c.agent for c in problem.constraints if isinstance(c, PointConstraint)}) if problem else []
    entries = []
    if pinned:
        names = ", ".join(map(str, pinned))
        entries.append(Line2D([], [], color=_PINNED, linewidth=1.6, label=f"constrained agent {names}"))
    entries.append(Line2D([], [], color=_FREE, linewidth=1, label="other agents" if pinned else "agents"))
    if ends:
        entries.append(Line2D([], [], linestyle="", marker="o", markersize=4, color="0.3", label="start"))
        entries.append(Line2D([], [], linestyle="", marker=">", markersize=6, color="black", label="end, heading"))
    if obstacles or (problem is not None and problem.obstacles):
        entries.append(Patch(facecolor="0.75", edgecolor="0.3", label="obstacle"))
    for label, color in zip(regions, _REGION_COLORS * len(regions)):
        entries.append(Patch(fill=False, edgecolor=color, linewidth=1.5, label=label))
    if PointConstraint in kinds:
        entries.append(Line2D([], [], linestyle="", marker="x", markersize=8, markeredgewidth=2, color="darkred",
                              label="point target"))  # fmt: skip
    if ComConstraint in kinds:
        entries.append(Line2D([], [], linestyle="", marker="*", markersize=11, color="tab:orange",
                              markeredgecolor="black", label="center-of-mass target"))  # fmt: skip
    if ShapeConstraint in kinds:
        entries.append(Patch(fill=False, edgecolor="tab:purple", linestyle="--", label="shape"))
    if inside:
        ax.legend(handles=entries, loc="best", fontsize=8)
    else:
        ax.figure.legend(handles=entries, loc="lower center", ncol=min(len(entries), 4), frameon=False, fontsize=8)


def animate(
    motion: Motion,
    path,
    *,
    problem=None,
    obstacles=(),
    regions=(),
    fps=None,
    size=None,
    trail=1.0,
    max_frames=None,
    progress=False,
    unit="m",
):
    """An animation of `motion`: agents as arrows facing their velocity, each with a trail, the
    scene as in plot_motion (with a `problem`, its point-constrained agents in red). ``.gif``
    through Pillow; ``.mp4`` through ffmpeg when it is on the PATH.

    It plays in real time by default: `fps` frames per second of video, default 1 / dt capped at
    MAX_FPS (25) by showing every k-th frame, so that k * dt seconds pass per video frame. `size`
    is (width, height) in pixels (default: 600 on the scene's longer side, the scene's
    proportions within 1:3 and 3:1, plus room for the title and legend), `trail` the seconds of
    path drawn behind each agent (0: none), `max_frames` an optional cap on the frames drawn
    (frames are then skipped evenly and the animation plays faster). Arrows are ARROW (5%) of
    the scene's extent long, whatever its units (a capture in pixels too); the axes say `unit` (as
    for plot_motion). `progress` shows a bar over the frames."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"animate needs a flockkit.Motion; got {type(motion).__name__}")
    path = movie_path(path)
    regions = _named(regions)
    trail = number(trail, "animate: trail (seconds)", minimum=0)
    plt = pyplot()
    frames, rate = timeline(motion.dt, motion.n_frames, fps, max_frames, "animate")
    xy, heading = motion.positions[..., :2], normalized(motion.velocities()[..., :2])
    low, high = _scene_bounds(xy, problem, obstacles, regions)
    keyed = problem is not None or bool(obstacles) or bool(regions)
    figure, ax = scene_figure(plt, low, high, size, keyed=keyed)
    _draw_scene(ax, problem, obstacles, regions)
    extent = fit_view(ax, low, high, unit=unit)
    if keyed:
        _legend(ax, problem, obstacles, regions, ends=False)
    colors = _roles(motion.n_agents, problem)
    from matplotlib.collections import LineCollection

    trails = LineCollection([], colors=colors, alpha=0.35, linewidths=0.8)  # one artist: drawn in one call
    ax.add_collection(trails)
    arrows = ax.quiver(
        xy[0, :, 0], xy[0, :, 1], heading[0, :, 0], heading[0, :, 1], angles="xy", scale_units="xy",
        scale=1.0 / (ARROW * extent), units="dots", width=2.5, headwidth=3.5, headlength=4, color=colors, zorder=4,
    )  # fmt: skip
    label = ax.set_title("")
    behind = round(trail / motion.dt)

    def draw(frame):
        arrows.set_offsets(xy[frame])
        arrows.set_UVC(heading[frame, :, 0], heading[frame, :, 1])
        first = max(0, frame - behind)
        trails.set_segments(np.swapaxes(xy[first : frame + 1], 0, 1))  # (agents, points, 2)
        label.set_text(f"t = {frame * motion.dt:.1f} s")
        return [arrows, label, trails]

    try:
        save_animation(figure, draw, frames, path, rate, progress)
    finally:
        plt.close(figure)
    return path


def _roles(n_agents: int, problem) -> list:
    """A colour per agent: red for point-constrained agents of `problem`, blue for the others."""
    pinned = set() if problem is None else {c.agent for c in problem.constraints if isinstance(c, PointConstraint)}
    return [_PINNED if agent in pinned else _FREE for agent in range(n_agents)]


def plot_trace(solution, path=None):
    """The sampler's log g per iteration for every chain of a flockkit.Solution, accepted
    proposals marked."""
    from ..constrained import Solution

    if not isinstance(solution, Solution):
        raise ValidationError(f"plot_trace needs a flockkit.Solution; got {type(solution).__name__}")
    if path is not None:
        path = picture_path(path)
    plt = pyplot()
    figure, ax = plt.subplots(figsize=(8, 4))
    for chain, trace in enumerate(solution.trace):
        iterations = np.arange(len(trace.log_g))
        ax.plot(iterations, trace.log_g, linewidth=1.0, label=f"chain {chain}")
        ax.scatter(iterations[trace.accepted], trace.log_g[trace.accepted], s=4)
    ax.set_xlabel("iteration")
    ax.set_ylabel("log g")
    ax.ticklabel_format(axis="y", useOffset=False)  # a refined start varies by units on a scale of 1e4
    ax.set_title("sampler trace (dots: accepted proposals)")
    if solution.trace:
        ax.legend(loc="lower right")
    if path is not None:
        save(figure, path)
    return figure
