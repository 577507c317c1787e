"""Pictures of crowds: a recorded crowd's stick figures, where they are or laid out on a grid,
and the offsets of a time dilation."""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError
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


def animate_recording(recording, path, *, layout="world", axes=None, fps=None, size=None, progress=False, pool=None,
                      title=None):  # fmt: skip
    """A recorded crowd (``flockkit.crowd.record``) as stick figures, joints joined to their
    parents, coloured by the stream each agent's part reads (while blending, by the stream it
    blends to, drawn thicker), seen along `axes` (horizontal, vertical). A legend below the
    figures names each stream's colour: by its ``Stream.name`` in `pool` (the StreamPool the crowd
    read) where it has one, else by its index; unique slots are one entry. `layout` "world": where
    they are (`axes` default "xy", from above); "grid": each agent in a cell of a grid, in place
    (`axes` default "xz", from the front), to see the poses of many. The title says `title`
    (default: how many agents) and the time. Returns the path."""
    path = movie_path(path)
    if layout not in ("world", "grid"):
        raise ValidationError(f"animate_recording: layout must be 'world' or 'grid'; got {layout!r}")
    axes = axes or ("xy" if layout == "world" else "xz")
    joints = recording.world()[..., :3, 3][..., _crowd_axes(axes)]
    if layout == "world":
        return _animate_skeletons(recording, joints, path, fps=fps, size=size, progress=progress, ticks=True,
                                  names=tuple(axes), pool=pool, title=title)  # fmt: skip
    agents = joints.shape[1]  # (frames, agents, J, 2)
    extent = np.ptp(joints.reshape(-1, 2), axis=0).max() if joints.size else 1.0
    spacing = 0.8 * max(float(np.ptp(joints[..., 0], axis=-1).max()), 1e-9) + 0.4 * extent / max(agents, 1) ** 0.5
    height = max(float(np.ptp(joints[..., 1], axis=-1).max()), 1e-9) * 1.4
    columns = max(1, int(np.ceil(np.sqrt(agents * height / spacing))))  # a roughly square crowd
    grid = np.stack([np.arange(agents) % columns, -(np.arange(agents) // columns)], axis=1)
    centers = joints.mean(axis=(0, 2))  # each agent's mean joint position: figures stay in their cells
    placed = joints - centers[None, :, None] + (grid * [spacing, height])[None, :, None]
    return _animate_skeletons(recording, placed, path, fps=fps, size=size, progress=progress, ticks=False, pool=pool,
                              title=title)  # fmt: skip


def _crowd_axes(axes) -> list[int]:
    if not isinstance(axes, str) or len(axes) != 2 or any(a not in "xyz" for a in axes) or axes[0] == axes[1]:
        raise ValidationError(f"axes must be two of 'x', 'y', 'z' (horizontal, vertical); got {axes!r}")
    return ["xyz".index(a) for a in axes]


# A recording's stream value for a unique slot is UNIQUE + slot; all unique slots share one colour.
UNIQUE = 1000
UNIQUE_COLOUR = "black"


def _stream_key(streams, pool) -> list[tuple[int, str]]:
    """(stream value, label) for each colour among `streams`: streams by name (from `pool`) or
    index, in index order, then every unique slot as one entry."""
    found = np.unique(streams)
    known = [getattr(s, "name", "") for s in getattr(pool, "streams", ())] if pool is not None else []
    if pool is not None and len(found) and found[found < UNIQUE].max(initial=-1) >= len(known):
        raise ValidationError(f"animate_recording: pool has {len(known)} streams; the recording reads stream "
                              f"{int(found[found < UNIQUE].max())}")  # fmt: skip
    key = [(int(s), (known[s] if s < len(known) and known[s] else f"stream {s}")) for s in found if s < UNIQUE]
    if (found >= UNIQUE).any():
        key.append((UNIQUE, "unique slots"))
    return key


def _animate_skeletons(recording, placed, path, *, fps, size, progress, ticks: bool, names=("x", "y"), pool=None,
                       title=None):  # fmt: skip
    """Draw `placed` (frames, agents, J, 2) joint positions of `recording` as stick figures, on
    axes named `names` (in metres) where `ticks`, with a legend of the streams' colours below."""
    parents = recording.skeleton.parents
    frames, rate = timeline(1.0 / recording.fps, recording.n_frames, fps, None, "animate_recording")
    plt = pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D

    low, high = placed.reshape(-1, 2).min(axis=0), placed.reshape(-1, 2).max(axis=0)
    figure, ax = scene_figure(plt, low, high, size, keyed=True, longer=640)
    # a driven crowd's roots place it in metres; otherwise joints are in the skeleton's own unit
    length = "m" if recording.axes else unit_name(recording.skeleton.meters_per_unit)
    fit_view(ax, low, high, names=names, unit=length if ticks else None)
    if not ticks:
        ax.set_xticks([])
        ax.set_yticks([])
    bones = np.flatnonzero(parents >= 0)
    palette = plt.get_cmap("tab10")

    def colour(stream):
        return UNIQUE_COLOUR if stream >= UNIQUE else palette(int(stream) % 10)

    tens, unique_rgba = np.array([palette(k) for k in range(10)]), np.array(to_rgba(UNIQUE_COLOUR))
    key = _stream_key(recording.streams[frames], pool)
    handles = [Line2D([], [], color=colour(s), lw=2) for s, _ in key]
    # in the band scene_figure keeps below the axes, under the tick labels: it covers no figure
    figure.legend(handles, [label for _, label in key], loc="lower center", bbox_to_anchor=(0.5, 0.0),
                  ncol=min(len(key), max(1, round(figure.bbox.width / 120))), fontsize=8, frameon=False)  # fmt: skip
    lines = LineCollection([], zorder=3)
    ax.add_collection(lines)
    label = ax.set_title("")
    title = title or f"{recording.n_agents} agents coloured by stream"

    def draw(index):
        frame = frames[index]
        segments = np.stack([placed[frame][:, bones], placed[frame][:, parents[bones]]], axis=2).reshape(-1, 2, 2)
        lines.set_segments(segments)
        streams = recording.streams[frame]
        rgba = np.where((streams >= UNIQUE)[:, None], unique_rgba, tens[streams % 10])  # (agents, 4)
        lines.set_color(np.repeat(rgba, len(bones), axis=0))
        lines.set_linewidth(np.repeat(np.where(recording.blending[frame], 2.2, 1.0), len(bones)))
        label.set_text(f"{title}, t = {frame / recording.fps:.1f} s")
        return [lines, label]

    try:
        save_animation(figure, draw, range(len(frames)), path, rate, progress)
    finally:
        plt.close(figure)
    return path


def plot_offsets(times, offsets, path=None, *, targets=None, title="offsets during time dilation"):
    """Agent parts' offsets (frames behind their stream's head) over `times` (F,) seconds:
    `offsets` (F, n), one line each, with their dilation `targets` (n,) dotted. Returns the
    Figure; writes it to `path` if given."""
    if path is not None:
        path = picture_path(path)
    times, offsets = np.asarray(times, dtype=float), np.asarray(offsets, dtype=float)
    if offsets.ndim != 2 or offsets.shape[0] != len(times):
        raise ValidationError(f"plot_offsets: offsets must be (len(times), parts); got {offsets.shape}")
    plt = pyplot()
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
        save(figure, path)
    return figure
