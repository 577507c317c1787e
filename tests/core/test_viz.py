import attrs
import numpy as np
import pytest

import flockkit
from flockkit import viz
from flockkit.errors import ValidationError

pytest.importorskip("matplotlib", reason="pictures need flockkit[viz]")


@pytest.fixture(scope="module")
def solved():
    problem = flockkit.Problem(
        n_agents=6,
        duration=2.0,
        constraints=[
            flockkit.PointConstraint(agent=0, time=1.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
            flockkit.ShapeConstraint(time=2.0, shape=flockkit.Box(lower=[0, -2], upper=[3, 2]), velocity=[1.0, 0.0]),
        ],
        obstacles=[flockkit.Ball(center=[5.0, 5.0], radius=1.0)],
    )
    return problem, flockkit.solve(problem, iterations=15, seed=1)


def test_a_gif_plays_in_real_time_at_its_size(tmp_path, solved):
    from PIL import Image

    problem, solution = solved
    viz.animate(solution.motion, tmp_path / "flock.gif", problem=problem, size=(320, 240))
    with Image.open(tmp_path / "flock.gif") as image:  # 10 Hz: every frame, 100 ms each
        assert image.n_frames == solution.motion.n_frames and image.size == (320, 240)
        assert image.info["duration"] == 100
    fast = flockkit.Motion(positions=np.cumsum(np.ones((90, 3, 2)), axis=0), dt=1 / 30)
    viz.animate(fast, tmp_path / "fast.gif", trail=0)
    with Image.open(tmp_path / "fast.gif") as image:  # 30 Hz: every other frame, 1/15 s each, 3 s in all
        assert image.n_frames == 45 and _gif_seconds(image) == pytest.approx(3.0, abs=0.005)
    viz.animate(fast, tmp_path / "slow.gif", fps=5)
    with Image.open(tmp_path / "slow.gif") as image:  # 5 fps asked: every 6th frame, still real time
        assert image.n_frames == 15 and image.info["duration"] == 200


def _gif_seconds(image) -> float:
    """How long a GIF plays: the sum of its frames' delays."""
    total = 0
    for k in range(image.n_frames):
        image.seek(k)
        total += image.info["duration"]
    return total / 1000


@pytest.mark.parametrize("rate", [24.0, 15.0, 30.0, 25.0, 12.0, 7.0])
def test_a_gif_lasts_its_motion_whatever_the_rate(tmp_path, rate):
    from PIL import Image

    # a motion whose every frame differs (Pillow merges equal frames, adding their delays)
    n = 37
    motion = flockkit.Motion(positions=np.cumsum(np.ones((n, 2, 2)), axis=0) * [1.0, 0.3], dt=1 / rate)
    viz.animate(motion, tmp_path / "timed.gif", trail=0, fps=rate)
    with Image.open(tmp_path / "timed.gif") as image:
        assert image.n_frames == n
        assert abs(_gif_seconds(image) - n / rate) <= 0.005  # GIF keeps hundredths of a second
        delays = []
        for k in range(n):
            image.seek(k)
            delays.append(image.info["duration"])
    starts = np.cumsum([0, *delays[:-1]]) / 1000
    assert np.abs(starts - np.arange(n) / rate).max() <= 0.005 + 1e-9  # every frame within 5 ms of its time


def test_arrows_scale_with_the_scene_whatever_its_units(tmp_path):
    from PIL import Image

    base = flockkit.simulate(n_agents=5, steps=20, seed=2)
    pictures = []
    for scale in (1.0, 500.0):  # the same flock in meters and in pixels
        motion = flockkit.Motion(positions=base.positions * scale, dt=base.dt)
        viz.animate(motion, tmp_path / f"{scale}.gif", trail=0, size=(200, 200))
        with Image.open(tmp_path / f"{scale}.gif") as image:
            pictures.append(np.asarray(image.convert("RGB")).astype(int))
    # the agents are blue; axes and labels (which differ with the units) are black
    inked = [int(np.count_nonzero((p[..., 2] > p[..., 0] + 40) & (p[..., 2] > p[..., 1] + 10))) for p in pictures]
    assert inked[0] > 40 and abs(inked[0] - inked[1]) <= 0.2 * inked[0]  # as visible in both units


def test_pictures_are_pngs(tmp_path, solved):
    problem, solution = solved
    graph = flockkit.build_graph(flockkit.simulate(n_agents=6, steps=200, seed=2))
    metric = flockkit.get("metric", "icp-hungarian")
    configs = [graph.motion.configuration(t) for t in range(0, 200, 10)]
    from scipy.spatial.distance import squareform

    drawings = {
        "still.png": lambda p: viz.plot_motion(
            solution.motion, p, problem=problem, regions=[flockkit.Box(lower=[-5, -5], upper=[5, 5])]
        ),
        "trace.png": lambda p: viz.plot_trace(solution, p),
        "graph.png": lambda p: viz.plot_graph(graph, p),
        "matrix.png": lambda p: viz.plot_difference_matrix(
            squareform(metric.pairwise(configs)), p, marked=[(2, 9), (9, 2)]
        ),
    }
    for name, draw in drawings.items():
        draw(tmp_path / name)
        assert (tmp_path / name).read_bytes().startswith(b"\x89PNG"), name


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda m, p: viz.animate(m, p / "flock.avi"), "unknown extension"),
        (lambda m, p: viz.plot_motion(m, p / "flock.gif"), "unknown extension"),
        (lambda m, p: viz.plot_graph(m, p / "g.png"), "MotionGraph"),
        (lambda m, p: viz.plot_trace(m, p / "t.png"), "Solution"),
        (lambda m, p: viz.plot_difference_matrix(np.zeros((3, 4)), p / "d.png"), "square"),
    ],
)
def test_bad_drawings_are_refused_and_nothing_is_written(tmp_path, solved, call, match):
    with pytest.raises(ValidationError, match=match):
        call(solved[1].motion, tmp_path)
    assert list(tmp_path.iterdir()) == []


def _legend_labels(figure):
    legends = [*figure.legends, *(ax.get_legend() for ax in figure.axes if ax.get_legend())]
    return [text.get_text() for legend in legends for text in legend.get_texts()]


def test_the_legend_names_every_kind_of_mark(solved):
    problem, solution = solved
    named = {"arena": flockkit.Box(lower=[-5, -5], upper=[8, 8])}
    labels = _legend_labels(viz.plot_motion(solution.motion, problem=problem, regions=named))
    expected = {"constrained agent 0", "other agents", "start", "end, heading", "obstacle", "arena", "point target",
                "shape"}  # fmt: skip
    assert set(labels) == expected
    plain = _legend_labels(viz.plot_motion(solution.motion, regions=[named["arena"]]))
    assert set(plain) == {"agents", "start", "end, heading", "region"}
    com = flockkit.Problem(
        n_agents=3,
        duration=1.0,
        constraints=[flockkit.ComConstraint(time=1.0, position=[1.0, 0.0], velocity=[1.0, 0.0])],
    )
    three = flockkit.simulate(n_agents=3, steps=10, seed=0)
    assert "center-of-mass target" in _legend_labels(viz.plot_motion(three, problem=com))


def test_a_wide_scene_fills_a_wide_canvas(tmp_path):
    """A flock crossing a long, narrow scene gets a picture in its proportions, not a square with
    a strip in the middle: its axes fill most of the canvas."""
    from PIL import Image

    x = np.linspace(0, 30, 61)[:, None, None] + np.array([[0.0], [0.5], [1.0]])[None]
    y = np.zeros_like(x) + np.array([0.0, 0.5, 1.0])[None, :, None]
    motion = flockkit.Motion(positions=np.concatenate([x, y], axis=2), dt=0.1)
    figure = viz.plot_motion(motion)
    ax = figure.axes[0]
    box = ax.get_position()
    width, height = figure.get_size_inches()
    assert width / height > 2  # wide like the scene
    drawn = ax.get_window_extent()
    assert drawn.width * drawn.height > 0.4 * figure.bbox.width * figure.bbox.height
    viz.animate(motion, tmp_path / "wide.gif", trail=0)
    with Image.open(tmp_path / "wide.gif") as image:
        assert image.size[0] == 600 and image.size[1] < 300
    assert box.width > 0.8


def test_the_graph_picture_keys_its_colours_and_turns():
    graph = flockkit.build_graph(flockkit.simulate(n_agents=6, steps=200, seed=2))
    figure = viz.plot_graph(graph)
    labels = _legend_labels(figure)
    stats = graph.stats()
    matched = stats["transitions"] - stats["turns"]
    assert f"matched transition, coloured by cost ({matched} of {stats['transitions']} transitions)" in labels
    assert any("node with turns of \u00b115\u00b0" in label for label in labels)
    assert any(ax.get_ylabel() == "transition cost E" for ax in figure.axes)  # the colour bar


def test_a_crowd_gif_colours_parts_by_stream_and_the_offsets_plot_shows_dilation(tmp_path, monkeypatch):
    from PIL import Image

    from flockkit.crowd import Crowd, Stream, StreamPool, record
    from flockkit.testing import inputs

    walker = inputs.walker()
    play = lambda **k: flockkit.get("controller", "clip", clip=walker, **k)  # noqa: E731
    pool = StreamPool(
        [Stream(controller=play(), history=30, name="walk"), Stream(controller=play(rate=1.7), history=30,
                                                                 default="Stopped")]
    )  # fmt: skip
    crowd = Crowd(pool, n_agents=6, clusters={"body": 0}, seed=0)

    def cheer(crowd, frame):
        if frame == 0:
            crowd.transition_to_streamed([0, 1, 2], "body", 1, blend_time=0.2, time_to_dilate=2.0)

    recording = record(crowd, 1.0, on_frame=cheer)
    from flockkit.viz import crowds

    keys, saved = [], crowds.save_animation

    def keep_key(figure, *args):  # the legend's labels, and whether it stays off the axes
        figure.canvas.draw()
        (legend,) = figure.legends
        ax = figure.axes[0].get_tightbbox(figure.canvas.get_renderer())
        keys.append(([t.get_text() for t in legend.get_texts()], legend.get_window_extent().y1 <= ax.y0))
        return saved(figure, *args)

    monkeypatch.setattr(crowds, "save_animation", keep_key)
    viz.animate_recording(recording, tmp_path / "crowd.gif", layout="grid", axes="yz", size=(320, 240), pool=pool)
    viz.animate_recording(recording, tmp_path / "world.gif", size=(320, 240))
    unique = attrs.evolve(recording, streams=np.where(np.arange(6) < 2, 1000 + np.arange(6), recording.streams))
    viz.animate_recording(unique, tmp_path / "unique.gif", layout="grid")
    assert keys == [(["walk", "stream 1"], True), (["stream 0", "stream 1"], True),
                    (["stream 0", "stream 1", "unique slots"], True)]  # fmt: skip
    with Image.open(tmp_path / "crowd.gif") as image:
        assert image.size == (320, 240) and image.n_frames == 15  # 1 s at 30 fps, drawn at 15
        image.seek(image.n_frames - 1)
        pixels = np.asarray(image.convert("RGB")).astype(int)[: 240 - 75]  # above the legend's band
    blue = (pixels[..., 2] > pixels[..., 0] + 40) & (pixels[..., 2] > 150)  # stream 0: tab10 blue
    orange = (pixels[..., 0] > pixels[..., 2] + 80) & (pixels[..., 1] > 80)  # stream 1: tab10 orange
    assert blue.sum() > 50 and orange.sum() > 50
    assert np.mean(np.flatnonzero(orange.any(axis=0))) < np.mean(
        np.flatnonzero(blue.any(axis=0))
    )  # agents 0-2 are left
    assert crowd.frame == 29  # the crowd ran: 30 frames kept, the first before any update
    figure = viz.plot_offsets(
        np.arange(4) / 30, np.array([[0, 0], [0.5, 0.4], [1, 0.8], [1.5, 0.8]]), tmp_path / "o.png", targets=[3, 0.8]
    )
    assert (tmp_path / "o.png").read_bytes().startswith(b"\x89PNG") and len(figure.axes[0].lines) == 4
    with pytest.raises(ValidationError, match="axes"):
        viz.animate_recording(recording, tmp_path / "bad.gif", axes="xw")
    assert not (tmp_path / "bad.gif").exists()


def test_a_gif_frame_is_the_figure_drawn_whole(tmp_path):
    """GIFs are blitted (the still part drawn once) and share one palette: a frame is what
    matplotlib draws of the whole figure, white kept exactly white, the rest within a level."""
    import matplotlib.pyplot as plt
    from PIL import Image

    from flockkit.viz._figures import save_animation

    figure, ax = plt.subplots(figsize=(3, 2), dpi=100)
    ax.set_xlim(0, 10)
    ax.set_ylim(-1.2, 1.2)
    (line,) = ax.plot([], [], color="tab:orange", lw=2)
    label = ax.set_title("")
    x = np.linspace(0, 10, 200)

    def draw(frame):
        line.set_data(x, np.sin(x + frame / 3))
        label.set_text(f"frame {frame}")
        return [line, label]

    save_animation(figure, draw, range(12), tmp_path / "wave.gif", 10.0, False)
    with Image.open(tmp_path / "wave.gif") as image:
        assert image.n_frames == 12 and image.info["duration"] == 100
        image.seek(7)
        frame = np.asarray(image.convert("RGB")).astype(int)
    for artist in (line, label):
        artist.set_animated(False)
    draw(7)
    figure.canvas.draw()
    whole = np.asarray(figure.canvas.buffer_rgba())[..., :3].astype(int)
    plt.close(figure)
    white = (whole == 255).all(axis=2)
    assert frame.shape == whole.shape and (frame[white] == 255).all()
    assert np.abs(frame - whole).mean() < 1.0


def test_every_world_axis_says_its_unit(solved):
    from flockkit.viz._figures import unit_name

    problem, solution = solved
    figure = viz.plot_motion(solution.motion, problem=problem)
    ax = figure.axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    pixels = viz.plot_motion(solution.motion, unit="px").axes[0]  # a capture in a video's pixels
    assert (pixels.get_xlabel(), pixels.get_ylabel()) == ("x (px)", "y (px)")
    assert [unit_name(f) for f in (1.0, 0.01, 0.0254, None, 0.3)] == ["m", "cm", "in", "units", "× 0.3 m"]


def test_scene_footprints_are_drawn_where_the_objects_start():
    """A flock's recording travels, so a walk starts away from the recording's mean center: the
    still draws each footprint about where its object is at t = 0, not where it was placed."""
    import matplotlib.patches as patches

    from flockkit.scene import Arrow, FlowField, Scene

    graph = flockkit.build_graph(flockkit.simulate(n_agents=6, steps=200, seed=2))
    wind = FlowField(arrows=[Arrow(position=[0.0, 0.0], keyframes=[(0.0, [0.7, 0.0])])])
    square = flockkit.Polygon(vertices=[[-60.0, -60.0], [60.0, -60.0], [60.0, 60.0], [-60.0, 60.0]])
    animation = Scene(templates=[graph], region=square, counts=[4], duration=2.0, constraints=[wind],
                      seed=2).synthesize()  # fmt: skip
    figure = viz.plot_scene(animation)
    boxes = [p for p in figure.axes[0].patches if isinstance(p, patches.Rectangle)]
    drawn = np.array([[b.get_x() + b.get_width() / 2, b.get_y() + b.get_height() / 2] for b in boxes])
    starts = np.array([m.positions[0, :, :2].mean(axis=0) for m in animation.motions])
    assert drawn.shape == starts.shape and np.abs(drawn - starts).max() < 1e-9
    assert np.linalg.norm(animation.placement.positions - starts, axis=1).max() > 1.0  # the case that was wrong
    sizes = np.array([[b.get_width(), b.get_height()] for b in boxes])
    placed = animation.bounding_boxes()
    assert np.allclose(sizes, placed[:, 1] - placed[:, 0])  # the same footprints, moved
