"""Pictures of flockkit values (extra ``viz``: matplotlib and pillow)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._atomic import atomic_path
from ._progress import progress_bar
from .constraints import ComConstraint, PointConstraint, ShapeConstraint
from .errors import MissingDependencyError, ValidationError
from .motion import Motion
from .validate import integer, number

__all__ = [
    "plot_motion",
    "animate",
    "plot_difference_matrix",
    "plot_graph",
    "plot_trace",
    "PICTURE_SUFFIXES",
    "ANIMATION_SUFFIXES",
]

PICTURE_SUFFIXES = (".png", ".pdf", ".svg")
ANIMATION_SUFFIXES = (".gif", ".mp4")


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("pictures need matplotlib: pip install 'flockkit[viz]'") from None
    return plt


def _check_picture_path(path, suffixes=PICTURE_SUFFIXES, what="picture") -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(
            f"{what} path {path}: unknown extension {path.suffix!r}; expected one of {', '.join(suffixes)}"
        )
    return path


def _draw_region(ax, region, **style):
    import matplotlib.patches as patches

    ax.add_patch(patches.Polygon(region.outline(), closed=True, **style))


def plot_motion(motion: Motion, path=None, *, problem=None, obstacles=(), regions=(), ax=None, title=None):
    """Draw every agent's trajectory (x-y plane), its start (dot) and end (arrow along the last
    velocity), obstacles (grey), regions (outlined) and, with a `problem`, its constraints: point
    targets (crosses), COM targets (stars) and shapes (dashed). Returns the matplotlib Figure;
    writes it to `path` if given (.png, .pdf or .svg; atomically)."""
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
    ax.quiver(
        xy[-1, :, 0],
        xy[-1, :, 1],
        travel[:, 0],
        travel[:, 1],
        color="black",
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.004,
        zorder=4,
        label="end",
    )
    _draw_scene(ax, problem, obstacles, regions)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(title or f"{motion.n_agents} agents, {motion.duration:g} s")
    ax.legend(loc="upper right")
    if path is not None:
        _save(figure, path)
    return figure


def _draw_scene(ax, problem, obstacles, regions):
    """Obstacles, regions and a problem's constraints, in the x-y plane."""
    obstacles = tuple(obstacles) + (tuple(problem.obstacles) if problem is not None else ())
    for obstacle in obstacles:
        _draw_region(ax, obstacle, facecolor="0.75", edgecolor="0.3")
    for region in regions:
        _draw_region(ax, region, fill=False, edgecolor="tab:blue", linewidth=1.5)
    if problem is None:
        return
    for c in problem.constraints:
        if isinstance(c, PointConstraint):
            ax.scatter(*c.position[:2], marker="x", s=60, color="tab:red", zorder=5)
        elif isinstance(c, ComConstraint):
            ax.scatter(*c.position[:2], marker="*", s=120, color="tab:orange", zorder=5)
        elif isinstance(c, ShapeConstraint):
            _draw_region(ax, c.shape, fill=False, edgecolor="tab:red", linestyle="--", linewidth=1.2)


def _save(figure, path: Path) -> None:
    """Write a figure atomically, then close it."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            figure.savefig(tmp, dpi=120, bbox_inches="tight")
    finally:
        plt.close(figure)


# GIF players and browsers show at most about 50 frames a second, and many fewer smoothly; above
# this rate frames are skipped evenly instead (our choice: 25, the PAL rate).
MAX_FPS = 25.0
# Arrow length as a share of the scene's extent: big enough to show a heading at 600 pixels (a
# 20-agent flock spread over 20 units gets arrows of 1 unit, 30 pixels), whatever the units.
ARROW = 0.05


def animate(
    motion: Motion,
    path,
    *,
    problem=None,
    obstacles=(),
    regions=(),
    fps=None,
    size=(600, 600),
    trail=1.0,
    max_frames=None,
    progress=False,
):
    """An animation of `motion`: agents as arrows facing their velocity, each with a trail, the
    scene as in plot_motion (with a `problem`, its point-constrained agents in red). ``.gif``
    through Pillow; ``.mp4`` through ffmpeg when it is on the PATH.

    It plays in real time by default: `fps` frames per second of video, default 1 / dt capped at
    MAX_FPS (25) by showing every k-th frame, so that k * dt seconds pass per video frame. `size`
    is (width, height) in pixels, `trail` the seconds of path drawn behind each agent (0: none),
    `max_frames` an optional cap on the frames drawn (frames are then skipped evenly and the
    animation plays faster). Arrows are ARROW (5%) of the scene's extent long, whatever its units
    (a capture in pixels too). `progress` shows a bar over the frames."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"animate needs a flockkit.Motion; got {type(motion).__name__}")
    path = _check_picture_path(path, ANIMATION_SUFFIXES, "animation")
    suffix = path.suffix.lower()
    fps = None if fps is None else number(fps, "animate: fps", minimum=0, strict=True)
    width, height = (integer(v, "animate: size", minimum=16) for v in _pair(size))
    trail = number(trail, "animate: trail (seconds)", minimum=0)
    plt = _pyplot()
    from matplotlib import animation

    if suffix == ".mp4" and not animation.FFMpegWriter.isAvailable():
        raise MissingDependencyError("MP4 animations need ffmpeg on the PATH; write a .gif instead")
    step = max(1, math.ceil((1.0 / motion.dt) / (fps or MAX_FPS) - 1e-9))
    if max_frames is not None:
        step = max(step, math.ceil(motion.n_frames / integer(max_frames, "animate: max_frames", minimum=1)))
    frames = np.arange(0, motion.n_frames, step)
    rate = fps or 1.0 / (motion.dt * step)
    xy, velocity = motion.positions[..., :2], motion.velocities()[..., :2]
    speed = np.linalg.norm(velocity, axis=2, keepdims=True)
    heading = np.divide(velocity, speed, out=np.zeros_like(velocity), where=speed > 1e-12)
    figure = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    ax = figure.add_subplot()
    _draw_scene(ax, problem, obstacles, regions)
    extent = _fit_view(ax, xy)
    colors = _roles(motion.n_agents, problem)
    trails = [ax.plot([], [], color=c, alpha=0.35, linewidth=0.8)[0] for c in colors]
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
        for agent, line in enumerate(trails):
            line.set_data(xy[first : frame + 1, agent, 0], xy[first : frame + 1, agent, 1])
        label.set_text(f"t = {frame * motion.dt:.1f} s")
        return [arrows, label, *trails]

    writer = animation.PillowWriter(fps=rate) if suffix == ".gif" else animation.FFMpegWriter(fps=rate)
    try:
        _save_animation(animation.FuncAnimation(figure, draw, frames=frames, blit=False), path, writer, progress)
    finally:
        plt.close(figure)
    return path


def _pair(size):
    try:
        width, height = size
    except (TypeError, ValueError):
        raise ValidationError(f"animate: size must be (width, height) in pixels; got {size!r}") from None
    return width, height


def _roles(n_agents: int, problem) -> list:
    """A colour per agent: red for point-constrained agents of `problem`, blue for the others."""
    pinned = set() if problem is None else {c.agent for c in problem.constraints if isinstance(c, PointConstraint)}
    return ["tab:red" if agent in pinned else "tab:blue" for agent in range(n_agents)]


def _fit_view(ax, xy) -> float:
    """Axis limits holding every position of (T, N, 2) `xy` with a margin, equal scales; returns
    the extent (the larger side) of the view in data units."""
    low, high = xy.reshape(-1, 2).min(axis=0), xy.reshape(-1, 2).max(axis=0)
    extent = max(float(np.max(high - low)), 1e-9)
    margin = 0.06 * extent + 1e-9
    ax.set_xlim(low[0] - margin, high[0] + margin)
    ax.set_ylim(low[1] - margin, high[1] + margin)
    ax.set_aspect("equal")
    return extent + 2 * margin


def _save_animation(movie, path, writer, progress: bool) -> None:
    """Write `movie` (a matplotlib animation) atomically, with a progress bar over its frames."""
    with progress_bar(progress, unit="frame") as report, atomic_path(path) as tmp:
        callback = None if report is None else (lambda done, total: report(done + 1, total, f"drawing {path.name}"))
        movie.save(tmp, writer=writer, progress_callback=callback)


def plot_difference_matrix(values, path=None, *, marked=(), title="difference matrix"):
    """The difference matrix E(t_i, t_j) (an array (K, K); +inf where not computed) as an image,
    with `marked` cells (pairs (i, j), e.g. the chosen transitions) circled."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[0] != values.shape[1]:
        raise ValidationError(f"plot_difference_matrix needs a square (K, K) array; got shape {values.shape}")
    if path is not None:
        path = _check_picture_path(path)
    plt = _pyplot()
    figure, ax = plt.subplots(figsize=(6.5, 6))
    shown = np.where(np.isfinite(values), values, np.nan)
    image = ax.imshow(shown, cmap="magma", origin="lower", interpolation="nearest")
    figure.colorbar(image, ax=ax, label="E")
    marked = np.asarray(list(marked), dtype=float).reshape(-1, 2)
    if len(marked):
        ax.scatter(
            marked[:, 1], marked[:, 0], s=30, facecolors="none", edgecolors="cyan", linewidths=1.0, label="transitions"
        )
        ax.legend(loc="upper left")
    ax.set_xlabel("candidate j")
    ax.set_ylabel("candidate i")
    ax.set_title(title)
    if path is not None:
        _save(figure, path)
    return figure


def plot_graph(graph, path=None):
    """A motion graph drawn along the source's time axis: nodes at their frames, clips as arcs
    below the axis, transitions as arcs above it (colored by cost)."""
    from .graph import MotionGraph

    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"plot_graph needs a flockkit.MotionGraph; got {type(graph).__name__}")
    if path is not None:
        path = _check_picture_path(path)
    plt = _pyplot()
    from matplotlib.patches import Arc

    figure, ax = plt.subplots(figsize=(10, 4))
    seconds = np.asarray(graph.nodes, dtype=float) * graph.motion.dt
    costs = np.array([t.alignment.distance for t in graph.transitions])
    cmap = plt.get_cmap("plasma")
    scale = costs.max() if len(costs) and costs.max() > 0 else 1.0
    for clip in graph.clips:
        a, b = seconds[clip.source], seconds[clip.target]
        ax.add_patch(
            Arc(((a + b) / 2, 0), abs(b - a), abs(b - a) * 0.3, theta1=180, theta2=360, color="0.5", linewidth=0.8)
        )
    for transition, cost in zip(graph.transitions, costs):
        a, b = seconds[transition.source], seconds[transition.target]
        ax.add_patch(
            Arc(
                ((a + b) / 2, 0),
                abs(b - a),
                abs(b - a) * 0.6,
                theta1=0,
                theta2=180,
                color=cmap(cost / scale),
                linewidth=0.8,
            )
        )
    ax.scatter(seconds, np.zeros_like(seconds), s=10, color="black", zorder=3)
    span = graph.motion.duration
    ax.set_xlim(-0.02 * span, 1.02 * span)
    ax.set_ylim(-0.17 * span, 0.32 * span)
    ax.set_yticks([])
    ax.set_xlabel("source time (s)")
    stats = graph.stats()
    ax.set_title(
        f"motion graph: {stats['nodes']} nodes, {stats['clips']} clips (below), {stats['transitions']} transitions "
        "(above)"
    )
    if path is not None:
        _save(figure, path)
    return figure


def plot_trace(solution, path=None):
    """The sampler's log g per iteration for every chain of a flockkit.Solution, accepted
    proposals marked."""
    from .solve import Solution

    if not isinstance(solution, Solution):
        raise ValidationError(f"plot_trace needs a flockkit.Solution; got {type(solution).__name__}")
    if path is not None:
        path = _check_picture_path(path)
    plt = _pyplot()
    figure, ax = plt.subplots(figsize=(8, 4))
    for chain, trace in enumerate(solution.trace):
        iterations = np.arange(len(trace.log_g))
        ax.plot(iterations, trace.log_g, linewidth=1.0, label=f"chain {chain}")
        ax.scatter(iterations[trace.accepted], trace.log_g[trace.accepted], s=4)
    ax.set_xlabel("iteration")
    ax.set_ylabel("log g")
    ax.set_title("sampler trace (dots: accepted proposals)")
    if solution.trace:
        ax.legend(loc="lower right")
    if path is not None:
        _save(figure, path)
    return figure
