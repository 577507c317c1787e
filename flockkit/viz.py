"""Pictures of flockkit values (extra ``viz``: matplotlib and pillow)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._atomic import atomic_path
from ._progress import progress_bar
from .constrained.problem import ComConstraint, PointConstraint, ShapeConstraint
from .errors import MissingDependencyError, ValidationError
from .motion import Motion
from .validate import integer, number

__all__ = [
    "plot_motion",
    "animate",
    "plot_mesh",
    "animate_mesh",
    "plot_difference_matrix",
    "plot_graph",
    "plot_trace",
    "animate_crowd",
    "animate_recording",
    "plot_offsets",
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
    """Draw every agent's trajectory (x-y plane), its start (dot) and end (arrow along its last
    heading, ARROW of the scene's extent long), obstacles (grey), `regions` (outlined; a
    sequence, or a mapping from legend label to region) and, with a `problem`, its
    constraints: point targets (crosses), COM targets (stars) and shapes (dashed),
    and its point-constrained agents in red, the others in blue. The legend names every kind of
    mark; the figure takes the scene's proportions. Returns the matplotlib Figure; writes it to
    `path` if given (.png, .pdf or .svg; atomically)."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"plot_motion needs a flockkit.Motion; got {type(motion).__name__}")
    if path is not None:
        path = _check_picture_path(path)
    regions = _named(regions)
    plt = _pyplot()
    xy = motion.positions[..., :2]
    low, high = _scene_bounds(xy, problem, obstacles, regions)
    given = ax is not None
    figure, ax = (ax.figure, ax) if given else _scene_figure(plt, low, high, None, keyed=True, longer=800)
    colors = _roles(motion.n_agents, problem)
    pinned = [c == _PINNED for c in colors]
    for agent in np.argsort(pinned, kind="stable"):  # the constrained agents on top
        ax.plot(xy[:, agent, 0], xy[:, agent, 1], color=colors[agent], linewidth=1.6 if pinned[agent] else 0.8,
                alpha=0.9 if pinned[agent] else 0.6)  # fmt: skip
    ax.scatter(xy[0, :, 0], xy[0, :, 1], s=10, color="0.3", zorder=3)
    extent = _fit_view(ax, low, high)
    heading = _unit(motion.velocities()[-1, :, :2]) * ARROW * extent
    ax.quiver(xy[-1, :, 0], xy[-1, :, 1], heading[:, 0], heading[:, 1], color=colors, angles="xy",
              scale_units="xy", scale=1.0, width=0.004, zorder=4)  # fmt: skip
    _draw_scene(ax, problem, obstacles, regions)
    ax.set_title(title or f"{motion.n_agents} agents, {motion.duration:g} s")
    _legend(ax, problem, obstacles, regions, inside=given)
    if path is not None:
        _save(figure, path)
    return figure


_PINNED, _FREE = "tab:red", "tab:blue"


def _scene_figure(plt, low, high, size, *, keyed: bool, longer: int = 600):
    """A figure and axes for the scene from `low` to `high`: `size` (width, height) in pixels, by
    default `longer` on the scene's longer side in its proportions (within 1:3 and 3:1), with
    room above for the title and below for tick labels and, if `keyed`, the legend."""
    title, key = 30, (75 if keyed else 25)  # pixels
    if size is None:
        ratio = float(np.clip((high[1] - low[1]) / max(high[0] - low[0], 1e-12), 1 / 3, 3))
        width = longer if ratio <= 1 else round(longer / ratio)
        size = (width, round(0.88 * width * ratio) + title + key)
    width, height = (integer(v, "animate: size", minimum=16) for v in _pair(size))
    figure = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    bottom, top = min(key / height, 0.4), max(1 - title / height, 0.6)
    return figure, figure.add_axes((0.08, bottom, 0.88, top - bottom))


def _unit(vectors) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 1e-12)


_REGION_COLORS = ("tab:green", "tab:olive", "tab:cyan", "tab:brown")


def _named(regions) -> dict:
    """`regions` (a sequence of regions, or a mapping from legend label to region) as a mapping."""
    from .regions import Region

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
        _draw_region(ax, obstacle, facecolor="0.75", edgecolor="0.3")
    for region, color in zip(regions.values(), _REGION_COLORS * len(regions)):
        _draw_region(ax, region, fill=False, edgecolor=color, linewidth=1.5)
    if problem is None:
        return
    for c in problem.constraints:
        if isinstance(c, PointConstraint):
            ax.scatter(*c.position[:2], marker="x", s=70, linewidths=2, color="darkred", zorder=5)
        elif isinstance(c, ComConstraint):
            ax.scatter(*c.position[:2], marker="*", s=140, color="tab:orange", edgecolors="black", zorder=5)
        elif isinstance(c, ShapeConstraint):
            _draw_region(ax, c.shape, fill=False, edgecolor="tab:purple", linestyle="--", linewidth=1.2)


def _legend(ax, problem, obstacles, regions, *, inside: bool = False, ends: bool = True) -> None:
    """A legend with one entry for every kind of mark drawn (`ends`: start dots and end arrows),
    at the bottom of the figure (where _scene_figure left room) or `inside` the axes."""
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
    size=None,
    trail=1.0,
    max_frames=None,
    progress=False,
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
    the scene's extent long, whatever its units (a capture in pixels too). `progress` shows a bar over the frames."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"animate needs a flockkit.Motion; got {type(motion).__name__}")
    path = _check_movie_path(path)
    regions = _named(regions)
    trail = number(trail, "animate: trail (seconds)", minimum=0)
    plt = _pyplot()
    frames, rate = _timeline(motion.dt, motion.n_frames, fps, max_frames, "animate")
    xy, heading = motion.positions[..., :2], _unit(motion.velocities()[..., :2])
    low, high = _scene_bounds(xy, problem, obstacles, regions)
    keyed = problem is not None or bool(obstacles) or bool(regions)
    figure, ax = _scene_figure(plt, low, high, size, keyed=keyed)
    _draw_scene(ax, problem, obstacles, regions)
    extent = _fit_view(ax, low, high)
    if keyed:
        _legend(ax, problem, obstacles, regions, ends=False)
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

    try:
        _save_animation(figure, draw, frames, path, rate, progress)
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
    return [_PINNED if agent in pinned else _FREE for agent in range(n_agents)]


def _fit_view(ax, low, high) -> float:
    """Axis limits holding the box from `low` to `high` with a margin, widened along one axis to
    the axes' own proportions so that scales are equal and the scene fills them; returns the
    extent (the larger side) of the view in data units."""
    extent = max(float(np.max(high - low)), 1e-9)
    margin = 0.06 * extent + 1e-9
    low, high = np.asarray(low, dtype=float) - margin, np.asarray(high, dtype=float) + margin
    box = ax.get_window_extent()
    wanted = box.height / max(box.width, 1e-9)  # height over width of the axes, on the canvas
    center, size = (low + high) / 2, high - low
    if size[1] / size[0] < wanted:
        size[1] = size[0] * wanted
    else:
        size[0] = size[1] / wanted
    ax.set_xlim(center[0] - size[0] / 2, center[0] + size[0] / 2)
    ax.set_ylim(center[1] - size[1] / 2, center[1] + size[1] / 2)
    ax.set_aspect("equal")
    return float(max(high - low))


def _check_movie_path(path) -> Path:
    """`path` checked as an animation's: a .gif, or an .mp4 where ffmpeg is on the PATH."""
    path = _check_picture_path(path, ANIMATION_SUFFIXES, "animation")
    if path.suffix.lower() == ".mp4":
        from matplotlib import animation

        if not animation.FFMpegWriter.isAvailable():
            raise MissingDependencyError("MP4 animations need ffmpeg on the PATH; write a .gif instead")
    return path


def _timeline(dt: float, n_frames: int, fps, max_frames, what: str) -> tuple[np.ndarray, float]:
    """(frames drawn, video frames per second): real time, `fps` (default 1 / dt capped at
    MAX_FPS) by showing every k-th frame, and at most `max_frames` frames when given."""
    fps = None if fps is None else number(fps, f"{what}: fps", minimum=0, strict=True)
    step = max(1, math.ceil((1.0 / dt) / (fps or MAX_FPS) - 1e-9))
    if max_frames is not None:
        step = max(step, math.ceil(n_frames / integer(max_frames, f"{what}: max_frames", minimum=1)))
    return np.arange(0, n_frames, step), fps or 1.0 / (dt * step)


# Frames, evenly spaced, whose colours make a GIF's palette: enough to see every colour a figure
# uses for a while (a stream's colour in a crowd); the others are matched to the nearest.
PALETTE_SAMPLES = 9


def _save_animation(figure, draw, frames, path, rate: float, progress: bool) -> None:
    """Write the animation `draw(frame)` makes of `figure` for each of `frames` atomically, at
    `rate` frames per second, with a progress bar over its frames; `draw` returns the artists it
    changed. An MP4 goes through matplotlib's ffmpeg writer.

    A GIF is blitted: the rest of the figure is drawn once and each frame draws only those
    artists over it, and all frames share one palette, made from PALETTE_SAMPLES of them.
    Matplotlib's Pillow writer draws each frame whole twice, axes and ticks included, and Pillow
    then picks a palette per frame, holding every frame in RGBA: 1 201 frames of 20 agents at 600
    pixels took 122.0 s and 2.1 GB that way, and take 11.6 s and 0.5 GB this way (`flockkit demo`:
    313 -> 70 s)."""
    frames, stage = list(frames), f"drawing {path.name}"
    with progress_bar(progress, unit="frame") as report, atomic_path(path) as tmp:
        if path.suffix.lower() != ".gif":
            from matplotlib import animation

            callback = None if report is None else (lambda done, total: report(done + 1, total, stage))
            movie = animation.FuncAnimation(figure, draw, frames=frames, blit=False)
            movie.save(tmp, writer=animation.FFMpegWriter(fps=rate), progress_callback=callback)
            return
        from PIL import Image

        canvas = figure.canvas
        for artist in draw(frames[0]):
            artist.set_animated(True)  # left out when the rest is drawn
        canvas.draw()
        background = canvas.copy_from_bbox(figure.bbox)

        def render(frame):
            changed = sorted(draw(frame), key=lambda artist: artist.get_zorder())
            canvas.restore_region(background)
            for artist in changed:
                figure.draw_artist(artist)
            return Image.fromarray(np.array(canvas.buffer_rgba())[..., :3])

        picks = np.unique(np.linspace(0, len(frames) - 1, PALETTE_SAMPLES).round().astype(int))
        palette = _shared_palette([render(frames[k]) for k in picks])

        def quantized():  # one at a time: Pillow keeps its own copy of each frame until it writes
            for done, frame in enumerate(frames):
                yield render(frame).quantize(palette=palette, dither=Image.Dither.NONE)
                if report is not None:
                    report(done + 1, len(frames), stage)

        images = quantized()
        next(images).save(tmp, format="GIF", save_all=True, append_images=images, duration=int(1000 / rate), loop=0)


def _shared_palette(images):
    """A GIF palette for frames like `images` (RGB): the most frequent colour of each cell of 32
    levels a channel, most frequent first. The background and the main colours stay exact (a
    median cut's palette, with near-white entries beside white, turned white into 252 grey)."""
    from PIL import Image

    strip = Image.new("RGB", (images[0].width, images[0].height * len(images)))
    for k, image in enumerate(images):
        strip.paste(image, (0, k * image.height))
    cells = {}
    for _, colour in sorted(strip.getcolors(strip.width * strip.height), reverse=True):
        cells.setdefault(tuple(value >> 3 for value in colour), colour)
    palette = Image.new("P", (1, 1))
    palette.putpalette([value for colour in list(cells.values())[:256] for value in colour])
    return palette


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

    from .mesh import AnimatedMesh

    if not isinstance(mesh, AnimatedMesh):
        raise ValidationError(f"drawing a mesh needs a flockkit.AnimatedMesh; got {type(mesh).__name__}")
    if segmentation is not None:
        segmentation.check_fits(mesh.motion, "the mesh")
    plt = _pyplot()
    horizontal, vertical, depth = _mesh_view(mesh, axes)
    flat = mesh.motion.positions[..., [horizontal, vertical]]
    low, high = flat.reshape(-1, 2).min(axis=0), flat.reshape(-1, 2).max(axis=0)
    figure, ax = _scene_figure(plt, low, high, size, keyed=segmentation is not None)
    _fit_view(ax, low, high)
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
        path = _check_picture_path(path)
    frame = integer(frame, "plot_mesh: frame", minimum=0)
    figure, ax, draw = _mesh_drawing(mesh, segmentation, axes, size, title="")
    if frame >= mesh.motion.n_frames:
        _pyplot().close(figure)
        raise ValidationError(f"plot_mesh: frame {frame} is past the mesh's {mesh.motion.n_frames} frames")
    ax.set_title(f"{mesh.name}, t = {frame * mesh.motion.dt:.2f} s")
    draw(frame)
    if path is not None:
        _save(figure, path)
    return figure


def animate_mesh(mesh, path, *, segmentation=None, axes=None, fps=None, size=None, progress=False):
    """An animation of a mesh, drawn as plot_mesh draws a frame, in real time (as animate)."""
    path = _check_movie_path(path)
    frames, rate = _timeline(mesh.motion.dt, mesh.motion.n_frames, fps, None, "animate_mesh")
    figure, ax, draw = _mesh_drawing(mesh, segmentation, axes, size, title=mesh.name)
    plt = _pyplot()
    label = ax.set_title("")

    def frame_and_time(frame):
        label.set_text(f"{mesh.name}, t = {frame * mesh.motion.dt:.1f} s")
        return [*draw(frame), label]

    try:
        _save_animation(figure, frame_and_time, frames, path, rate, progress)
    finally:
        plt.close(figure)
    return path


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
    below the axis, transitions as arcs above it coloured by cost (the colour bar), turns as
    triangles on the nodes that offer them; the legend names each."""
    from .graphs import MotionGraph

    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"plot_graph needs a flockkit.MotionGraph; got {type(graph).__name__}")
    if path is not None:
        path = _check_picture_path(path)
    plt = _pyplot()
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D
    from matplotlib.patches import Arc

    figure, ax = plt.subplots(figsize=(10, 4.2))
    seconds = np.asarray(graph.nodes, dtype=float) * graph.motion.dt
    matched = [t for t in graph.transitions if not t.is_turn]
    costs = np.array([t.alignment.distance for t in matched])
    cmap = plt.get_cmap("plasma")
    norm = Normalize(costs.min(), costs.max()) if len(costs) and costs.max() > costs.min() else Normalize(0.0, 1.0)
    for clip in graph.clips:
        a, b = seconds[clip.source], seconds[clip.target]
        ax.add_patch(Arc(((a + b) / 2, 0), b - a, (b - a) * 0.3, theta1=180, theta2=360, color="0.5", linewidth=0.8))
    for transition, cost in zip(matched, costs):
        a, b = seconds[transition.source], seconds[transition.target]
        width = abs(b - a)
        ax.add_patch(
            Arc(((a + b) / 2, 0), width, width * 0.6, theta1=0, theta2=180, color=cmap(norm(cost)), linewidth=0.8)
        )
    span = graph.motion.duration
    turning = sorted({t.source for t in graph.transitions if t.is_turn})
    lift = 0.02 * max([abs(seconds[t.target] - seconds[t.source]) for t in matched] + [0.05 * span])
    ax.scatter(seconds[turning], np.full(len(turning), lift), marker="^", s=14, color="tab:green", zorder=3)
    ax.scatter(seconds, np.zeros_like(seconds), s=10, color="black", zorder=4)
    ax.set_xlim(-0.02 * span, 1.02 * span)
    reach = max([abs(seconds[t.target] - seconds[t.source]) for t in matched] + [0.05 * span])
    dip = max([float(seconds[c.target] - seconds[c.source]) for c in graph.clips] + [0.05 * span])
    ax.set_ylim(-0.15 * dip - 0.03 * reach, 0.36 * reach)  # arcs rise 0.3 of their width, clips dip 0.15
    ax.set_yticks([])
    ax.set_xlabel("source time (s)")
    figure.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, label="transition cost E", pad=0.01)
    stats = graph.stats()
    angle = graph.params.get("turn_angle")
    entries = [
        Line2D([], [], linestyle="", marker="o", markersize=4, color="black", label=f"node ({stats['nodes']})"),
        Line2D([], [], color="0.5", label=f"clip: plays the recording ({stats['clips']})"),
        Line2D([], [], color=cmap(0.5), label=f"transition, coloured by cost ({len(matched)})"),
    ]
    if turning:
        about = f" of \u00b1{angle:g}\u00b0" if isinstance(angle, (int, float)) else ""
        label = f"node with turns{about} ({len(turning)} nodes, {stats['turns']} turns)"
        entries.append(Line2D([], [], linestyle="", marker="^", color="tab:green", label=label))
    ax.legend(handles=entries, loc="upper left", fontsize=8, frameon=False)
    ax.set_title(f"motion graph of {span:g} s of recording")
    if path is not None:
        _save(figure, path)
    return figure


def plot_trace(solution, path=None):
    """The sampler's log g per iteration for every chain of a flockkit.Solution, accepted
    proposals marked."""
    from .constrained import Solution

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
    ax.ticklabel_format(axis="y", useOffset=False)  # a refined start varies by units on a scale of 1e4
    ax.set_title("sampler trace (dots: accepted proposals)")
    if solution.trace:
        ax.legend(loc="lower right")
    if path is not None:
        _save(figure, path)
    return figure


def plot_scene(animation, path=None, *, times=None, size=None):
    """Top view of a SceneAnimation: the region's objects as their footprint boxes (one colour per
    template) and the flow arrows at a few `times` (default: start, middle and end), darker as
    time goes on; self-moving objects' arrows are drawn on them. Returns the Figure; writes it to
    `path` if given."""
    import matplotlib.patches as patches

    plt = _pyplot()
    path = None if path is None else _check_picture_path(path)
    from .scene import FlowField, SelfMovement

    boxes = animation.bounding_boxes()
    low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
    flows = [c for c in animation.constraints if isinstance(c, FlowField)]
    for flow in flows:
        points = np.stack([a.position[:2] for a in flow.arrows])
        low, high = np.minimum(low, points.min(axis=0)), np.maximum(high, points.max(axis=0))
    figure, ax = _scene_figure(plt, low, high, size, keyed=True)
    duration = (animation.n_frames - 1) * animation.dt
    times = [0.0, duration / 2, duration] if times is None else list(times)
    colours = plt.get_cmap("tab10")
    for box, kind in zip(boxes, animation.placement.templates):
        ax.add_patch(patches.Rectangle(box[0], *(box[1] - box[0]), fill=False, lw=0.6, color=colours(int(kind) % 10)))
    reach = 0.15 * float(np.max(high - low))
    shades = plt.get_cmap("Reds")(np.linspace(0.4, 1.0, len(times)))
    for shade, when in zip(shades, times):
        label = f"flow at t = {when:g} s"
        for flow in flows:
            points = np.stack([a.position[:2] for a in flow.arrows])
            vectors = np.stack([a.at([when])[0][:2] for a in flow.arrows]) * reach
            ax.quiver(*points.T, *vectors.T, color=shade, angles="xy", scale_units="xy", scale=1, width=0.006,
                      label=label)  # fmt: skip
            label = None
        for mover in (c for c in animation.constraints if isinstance(c, SelfMovement)):
            where = animation.placement.positions[mover.object]
            arrow = mover.targets([when])[0][:2] * reach
            ax.quiver(*where, *arrow, color=shade, angles="xy", scale_units="xy", scale=1, width=0.004)
    ax.plot([], [], color=colours(0), lw=1, label=f"{animation.placement.n_objects} objects (footprints)")
    if animation.region is not None:
        _draw_region(ax, animation.region, fill=False, edgecolor="tab:green", lw=1.2, label="region")
        low, high = np.minimum(low, animation.region.bounds()[0]), np.maximum(high, animation.region.bounds()[1])
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), ncol=3, fontsize=8, frameon=False)
    ax.set_title(f"scene: {animation.placement.n_objects} objects, {duration:g} s")
    _fit_view(ax, low, high)
    if path is not None:
        _save(figure, path)
    return figure


# Points drawn per object in a scene animation at most (evenly chosen): a field of meshes of
# thousands of vertices each reads as well from a few dozen, and draws a hundred times faster.
SCENE_POINTS = 48


def animate_scene(animation, path, *, fps=None, size=None, max_frames=None, progress=False):
    """A top-view animation of a SceneAnimation: every object's points (up to SCENE_POINTS of
    them, one colour per template) over the region, with the flow arrows turning as they are
    keyframed. Timing, `size`, `max_frames` and formats as for animate. Returns the path."""
    path = _check_movie_path(path)
    frames, rate = _timeline(animation.dt, animation.n_frames, fps, max_frames, "animate_scene")
    plt = _pyplot()

    from .scene import FlowField

    xy, colours = [], []
    palette = plt.get_cmap("tab10")
    for motion, kind in zip(animation.motions, animation.placement.templates):
        chosen = np.linspace(0, motion.n_agents - 1, min(motion.n_agents, SCENE_POINTS)).round().astype(int)
        xy.append(motion.positions[frames][:, np.unique(chosen), :2])
        colours += [palette(int(kind) % 10)] * xy[-1].shape[1]
    xy = np.concatenate(xy, axis=1)  # (frames drawn, points, 2)
    boxes = animation.bounding_boxes()
    low, high = (
        np.minimum(xy.min(axis=(0, 1)), boxes[:, 0].min(axis=0)),
        np.maximum(xy.max(axis=(0, 1)), boxes[:, 1].max(axis=0)),
    )
    if animation.region is not None:
        low, high = np.minimum(low, animation.region.bounds()[0]), np.maximum(high, animation.region.bounds()[1])
    figure, ax = _scene_figure(plt, low, high, size, keyed=False)
    if animation.region is not None:
        _draw_region(ax, animation.region, fill=False, edgecolor="tab:green", lw=1.2)
    extent = _fit_view(ax, low, high)
    dots = ax.scatter(xy[0, :, 0], xy[0, :, 1], s=2, c=colours, zorder=3)
    arrows = [a for c in animation.constraints if isinstance(c, FlowField) for a in c.arrows]
    bases = np.array([a.position[:2] for a in arrows]).reshape(-1, 2)
    still = np.zeros(len(bases))
    quiver = ax.quiver(*bases.T, still, still, color="tab:red", angles="xy", scale_units="xy",
                       scale=1.0 / (3 * ARROW * extent), width=0.006, zorder=4)  # fmt: skip
    label = ax.set_title("")

    def draw(index):
        dots.set_offsets(xy[index])
        when = frames[index] * animation.dt
        if len(arrows):
            vectors = np.array([a.at([when])[0][:2] for a in arrows])
            quiver.set_UVC(vectors[:, 0], vectors[:, 1])
        label.set_text(f"{animation.placement.n_objects} objects, t = {when:.1f} s")
        return [dots, quiver, label]

    try:
        _save_animation(figure, draw, range(len(frames)), path, rate, progress)
    finally:
        plt.close(figure)
    return path


def animate_crowd(crowd, path, *, seconds: float = 3.0, cluster=None, agents=None, on_frame=None, axes="xz",
                  fps=None, size=None, progress=False):  # fmt: skip
    """Run `crowd` (a ``flockkit.Crowd``) for `seconds` and draw it: each of `agents` (default up
    to the first 48) a stick figure of its part `cluster` (default the first), joints joined to
    their parents, laid out on a grid and seen along the axes `axes` (horizontal, vertical),
    coloured by the stream the part reads (while blending, by the stream it blends to, drawn
    thicker). The crowd advances, as a game loop would advance it; ``on_frame(crowd, frame)`` is
    called before each update, to start transitions. Returns the path."""
    from .crowd.record import record

    path = _check_movie_path(path)
    pick = _crowd_axes(axes)
    seconds = number(seconds, "animate_crowd: seconds", minimum=0, strict=True)
    agents = np.arange(min(crowd.n_agents, 48)) if agents is None else np.asarray(agents)
    recording = record(crowd, seconds, agents=agents, cluster=cluster, on_frame=on_frame)
    joints = recording.world()[..., :3, 3][..., pick]  # (frames, agents, J, 2)
    extent = np.ptp(joints.reshape(-1, 2), axis=0).max() if joints.size else 1.0
    spacing = 0.8 * max(float(np.ptp(joints[..., 0], axis=-1).max()), 1e-9) + 0.4 * extent / max(len(agents), 1) ** 0.5
    height = max(float(np.ptp(joints[..., 1], axis=-1).max()), 1e-9) * 1.4
    columns = max(1, int(np.ceil(np.sqrt(len(agents) * height / spacing))))  # a roughly square crowd
    grid = np.stack([np.arange(len(agents)) % columns, -(np.arange(len(agents)) // columns)], axis=1)
    centers = joints.mean(axis=(0, 2))  # each agent's mean joint position: figures stay in their cells
    placed = joints - centers[None, :, None] + (grid * [spacing, height])[None, :, None]
    return _animate_skeletons(recording, placed, path, fps=fps, size=size, progress=progress, ticks=False)


def animate_recording(recording, path, *, axes="xy", fps=None, size=None, progress=False):
    """A recorded crowd (``flockkit.crowd.record``) where it is in the world, seen along `axes`
    (default from above): each agent a stick figure coloured by its stream, blending ones
    thicker. Returns the path."""
    path = _check_movie_path(path)
    placed = recording.world()[..., :3, 3][..., _crowd_axes(axes)]
    return _animate_skeletons(recording, placed, path, fps=fps, size=size, progress=progress, ticks=True)


def _crowd_axes(axes) -> list[int]:
    if not isinstance(axes, str) or len(axes) != 2 or any(a not in "xyz" for a in axes) or axes[0] == axes[1]:
        raise ValidationError(f"axes must be two of 'x', 'y', 'z' (horizontal, vertical); got {axes!r}")
    return ["xyz".index(a) for a in axes]


def _animate_skeletons(recording, placed, path, *, fps, size, progress, ticks: bool):
    """Draw `placed` (frames, agents, J, 2) joint positions of `recording` as stick figures."""
    parents = recording.skeleton.parents
    frames, rate = _timeline(1.0 / recording.fps, recording.n_frames, fps, None, "animate_crowd")
    plt = _pyplot()
    from matplotlib.collections import LineCollection

    low, high = placed.reshape(-1, 2).min(axis=0), placed.reshape(-1, 2).max(axis=0)
    figure, ax = _scene_figure(plt, low, high, size, keyed=False, longer=640)
    _fit_view(ax, low, high)
    if not ticks:
        ax.set_xticks([])
        ax.set_yticks([])
    bones = np.flatnonzero(parents >= 0)
    palette = plt.get_cmap("tab10")
    lines = LineCollection([], zorder=3)
    ax.add_collection(lines)
    label = ax.set_title("")

    def draw(index):
        frame = frames[index]
        segments = np.stack([placed[frame][:, bones], placed[frame][:, parents[bones]]], axis=2).reshape(-1, 2, 2)
        lines.set_segments(segments)
        lines.set_color([palette(int(s) % 10) for s in recording.streams[frame] for _ in bones])
        lines.set_linewidth([2.2 if b else 1.0 for b in recording.blending[frame] for _ in bones])
        label.set_text(f"{recording.n_agents} agents coloured by stream, t = {(frame + 1) / recording.fps:.1f} s")
        return [lines, label]

    try:
        _save_animation(figure, draw, range(len(frames)), path, rate, progress)
    finally:
        plt.close(figure)
    return path


def plot_offsets(times, offsets, path=None, *, targets=None, title="offsets during time dilation"):
    """Agent parts' offsets (frames behind their stream's head) over `times` (F,) seconds:
    `offsets` (F, n), one line each, with their dilation `targets` (n,) dotted. Returns the
    Figure; writes it to `path` if given."""
    if path is not None:
        path = _check_picture_path(path)
    times, offsets = np.asarray(times, dtype=float), np.asarray(offsets, dtype=float)
    if offsets.ndim != 2 or offsets.shape[0] != len(times):
        raise ValidationError(f"plot_offsets: offsets must be (len(times), parts); got {offsets.shape}")
    plt = _pyplot()
    figure, ax = plt.subplots(figsize=(7, 3.6))
    palette = plt.get_cmap("viridis")
    order = np.argsort(offsets[-1])
    for rank, k in enumerate(order):
        colour = palette(rank / max(len(order) - 1, 1))
        ax.plot(times, offsets[:, k], color=colour, lw=1)
        if targets is not None:
            ax.axhline(float(np.asarray(targets)[k]), color=colour, lw=0.6, ls=":")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("offset (frames behind the head)")
    ax.set_title(title)
    if path is not None:
        _save(figure, path)
    return figure
