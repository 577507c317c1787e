"""Pictures of motion graphs: a difference matrix with its transitions, and a graph's nodes and
edges along its source."""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError
from ._figures import (
    picture_path,
    pyplot,
    save,
)


def plot_difference_matrix(values, path=None, *, marked=(), title="difference matrix"):
    """The difference matrix E(t_i, t_j) (an array (K, K); +inf where not computed) as an image,
    with `marked` cells (pairs (i, j), e.g. the chosen transitions) circled."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[0] != values.shape[1]:
        raise ValidationError(f"plot_difference_matrix needs a square (K, K) array; got shape {values.shape}")
    if path is not None:
        path = picture_path(path)
    plt = pyplot()
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
        save(figure, path)
    return figure


def plot_graph(graph, path=None):
    """A motion graph drawn along the source's time axis: nodes at their frames, clips as arcs
    below the axis, transitions as arcs above it coloured by cost (the colour bar), turns as
    triangles on the nodes that offer them; the legend names each."""
    from ..graphs import MotionGraph

    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"plot_graph needs a flockkit.MotionGraph; got {type(graph).__name__}")
    if path is not None:
        path = picture_path(path)
    plt = pyplot()
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
        Line2D(
            [],
            [],
            color=cmap(0.5),
            label=f"matched transition, coloured by cost ({len(matched)} of {stats['transitions']} transitions)",
        ),  # fmt: skip
    ]
    if turning:
        about = f" of \u00b1{angle:g}\u00b0" if isinstance(angle, (int, float)) else ""
        label = f"node with turns{about} ({len(turning)} nodes, {stats['turns']} turns)"
        entries.append(Line2D([], [], linestyle="", marker="^", color="tab:green", label=label))
    ax.legend(handles=entries, loc="upper left", fontsize=8, frameon=False)
    ax.set_title(f"motion graph of {span:g} s of recording")
    if path is not None:
        save(figure, path)
    return figure
