"""Pictures of background scenes: a top view of every object with its arrows, and its animation."""

from __future__ import annotations

import numpy as np

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


def plot_scene(animation, path=None, *, times=None, size=None):
    """Top view of a SceneAnimation: the region's objects as their footprint boxes where they are at
    t = 0 (one colour per template; see :func:`starting_boxes`) and the flow arrows at a few
    `times` (default: start, middle and end), darker as time goes on; self-moving objects' arrows
    are drawn where those objects are then. Returns the Figure; writes it to `path` if given."""
    import matplotlib.patches as patches

    plt = pyplot()
    path = None if path is None else picture_path(path)
    from ..scene import FlowField, SelfMovement

    boxes = starting_boxes(animation)
    low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
    places = animation.transforms()[0]  # (objects, frames, 2)
    flows = [c for c in animation.constraints if isinstance(c, FlowField)]
    for flow in flows:
        points = np.stack([a.position[:2] for a in flow.arrows])
        low, high = np.minimum(low, points.min(axis=0)), np.maximum(high, points.max(axis=0))
    figure, ax = scene_figure(plt, low, high, size, keyed=True)
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
            where = places[mover.object, min(max(round(when / animation.dt), 0), animation.n_frames - 1)]
            arrow = mover.targets([when])[0][:2] * reach
            ax.quiver(*where, *arrow, color=shade, angles="xy", scale_units="xy", scale=1, width=0.004)
    ax.plot([], [], color=colours(0), lw=1, label=f"{animation.placement.n_objects} objects (footprints at t = 0)")
    if animation.region is not None:
        draw_region(ax, animation.region, fill=False, edgecolor="tab:green", lw=1.2, label="region")
        low, high = np.minimum(low, animation.region.bounds()[0]), np.maximum(high, animation.region.bounds()[1])
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, fontsize=8, frameon=False)
    ax.set_title(f"scene: {animation.placement.n_objects} objects, {duration:g} s")
    fit_view(ax, low, high)
    if path is not None:
        save(figure, path)
    return figure


def starting_boxes(animation) -> np.ndarray:
    """(objects, 2, 2): the (low, high) corners in x, y of each object's footprint box where it is
    at t = 0: about its points' mean at its first frame. A footprint is the box around a template's
    shape about its own center of mass, and a walk starts wherever in its recording it starts (a
    flock's recording travels), so the placed position alone can sit far from the object."""
    boxes = animation.bounding_boxes()
    starts = np.stack([motion.positions[0, :, :2].mean(axis=0) for motion in animation.motions])
    return boxes - boxes.mean(axis=1, keepdims=True) + starts[:, None]


# Points drawn per object in a scene animation at most (evenly chosen): a field of meshes of
# thousands of vertices each reads as well from a few dozen, and draws a hundred times faster.
SCENE_POINTS = 48


def animate_scene(animation, path, *, fps=None, size=None, max_frames=None, progress=False):
    """A top-view animation of a SceneAnimation: every object's points (up to SCENE_POINTS of
    them, one colour per template) over the region, with the flow arrows turning as they are
    keyframed. Timing, `size`, `max_frames` and formats as for animate. Returns the path."""
    path = movie_path(path)
    frames, rate = timeline(animation.dt, animation.n_frames, fps, max_frames, "animate_scene")
    plt = pyplot()

    from ..scene import FlowField

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
    figure, ax = scene_figure(plt, low, high, size, keyed=False)
    if animation.region is not None:
        draw_region(ax, animation.region, fill=False, edgecolor="tab:green", lw=1.2)
    extent = fit_view(ax, low, high)
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
        save_animation(figure, draw, range(len(frames)), path, rate, progress)
    finally:
        plt.close(figure)
    return path
