"""What every picture and animation shares: matplotlib on its file backend, checked output
suffixes, figures sized for a scene, equal-scale views, atomic saves, and animations written
frame by frame on one palette."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .._atomic import atomic_path
from .._progress import progress_bar
from ..errors import MissingDependencyError, ValidationError
from ..validate import integer, number

PICTURE_SUFFIXES = (".png", ".pdf", ".svg")

ANIMATION_SUFFIXES = (".gif", ".mp4")


def pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("pictures need matplotlib: pip install 'flockkit[viz]'") from None
    return plt


def picture_path(path, suffixes=PICTURE_SUFFIXES, what="picture") -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(
            f"{what} path {path}: unknown extension {path.suffix!r}; expected one of {', '.join(suffixes)}"
        )
    return path


def draw_region(ax, region, **style):
    import matplotlib.patches as patches

    ax.add_patch(patches.Polygon(region.outline(), closed=True, **style))


def scene_figure(plt, low, high, size, *, keyed: bool, longer: int = 600):
    """A figure and axes for the scene from `low` to `high`: `size` (width, height) in pixels, by
    default `longer` on the scene's longer side in its proportions (within 1:3 and 3:1), with
    room (in pixels, so that an animation, saved without a tight bounding box, keeps them) above
    for the title, left for the y tick labels and axis name, below for the x tick labels and
    axis name and, if `keyed`, the legend."""
    title, left, right, key = 30, 62, 12, (92 if keyed else 42)  # pixels
    if size is None:
        ratio = float(np.clip((high[1] - low[1]) / max(high[0] - low[0], 1e-12), 1 / 3, 3))
        width = longer if ratio <= 1 else round(longer / ratio)
        size = (width, round((width - left - right) * ratio) + title + key)
    width, height = (integer(v, "animate: size", minimum=16) for v in pair(size))
    figure = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    bottom, top = min(key / height, 0.4), max(1 - title / height, 0.6)
    start = min(left / width, 0.3)
    return figure, figure.add_axes((start, bottom, max(1 - start - right / width, 0.4), top - bottom))


def unit(vectors) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 1e-12)


def save(figure, path: Path) -> None:
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


def pair(size):
    try:
        width, height = size
    except (TypeError, ValueError):
        raise ValidationError(f"animate: size must be (width, height) in pixels; got {size!r}") from None
    return width, height


def unit_name(meters_per_unit) -> str:
    """The unit a length is in, for an axis label: "m", "cm", "mm", "in", "ft", "km", other
    factors as "× 0.3 m", and "units" where none is stated (None)."""
    if meters_per_unit is None:
        return "units"
    named = {1.0: "m", 0.01: "cm", 0.001: "mm", 0.0254: "in", 0.3048: "ft", 1000.0: "km"}
    found = next((name for factor, name in named.items() if math.isclose(meters_per_unit, factor, rel_tol=1e-9)), None)
    return found or f"× {meters_per_unit:g} m"


def fit_view(ax, low, high, *, names=("x", "y"), unit: str | None = "m") -> float:
    """Axis limits holding the box from `low` to `high` with a margin, widened along one axis to
    the axes' own proportions so that scales are equal and the scene fills them; the axes are
    labelled with their `names` and `unit` (flockkit's world is in metres; None: no labels).
    Returns the extent (the larger side) of the view in data units."""
    if unit is not None:
        ax.set_xlabel(f"{names[0]} ({unit})", fontsize=8)
        ax.set_ylabel(f"{names[1]} ({unit})", fontsize=8)
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


def movie_path(path) -> Path:
    """`path` checked as an animation's: a .gif, or an .mp4 where ffmpeg is on the PATH."""
    path = picture_path(path, ANIMATION_SUFFIXES, "animation")
    if path.suffix.lower() == ".mp4":
        from matplotlib import animation

        if not animation.FFMpegWriter.isAvailable():
            raise MissingDependencyError("MP4 animations need ffmpeg on the PATH; write a .gif instead")
    return path


def timeline(dt: float, n_frames: int, fps, max_frames, what: str) -> tuple[np.ndarray, float]:
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


def save_animation(figure, draw, frames, path, rate: float, progress: bool) -> None:
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
            width, height = canvas.get_width_height(physical=True)
            return Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")

        picks = np.unique(np.linspace(0, len(frames) - 1, PALETTE_SAMPLES).round().astype(int))
        palette = shared_palette([render(frames[k]) for k in picks])

        def quantized():  # one at a time: Pillow keeps its own copy of each frame until it writes
            for done, frame in enumerate(frames):
                yield render(frame).quantize(palette=palette, dither=Image.Dither.NONE)
                if report is not None:
                    report(done + 1, len(frames), stage)

        images = quantized()
        durations = gif_durations(len(frames), rate)
        next(images).save(tmp, format="GIF", save_all=True, append_images=images, duration=durations, loop=0)


def gif_durations(n_frames: int, rate: float) -> list[int]:
    """Milliseconds each of `n_frames` GIF frames shows at `rate` frames per second. GIF keeps
    hundredths of a second, so one delay for all (1000 / 24 -> 40 ms) runs fast or slow; instead
    frame k shows from its true start time rounded to 10 ms until the next's (24 fps: 40, 40, 50,
    ...), so every frame starts within 5 ms of its time and the whole lasts n_frames / rate."""
    ticks = np.round(np.arange(n_frames + 1) * (100.0 / rate)).astype(np.int64)  # hundredths of a second
    return [int(d) * 10 for d in np.diff(ticks)]


def shared_palette(images):
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
