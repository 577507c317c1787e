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


def test_a_gif_has_one_frame_per_motion_frame(tmp_path, solved):
    from PIL import Image

    problem, solution = solved
    viz.animate(solution.motion, tmp_path / "flock.gif", problem=problem)
    with Image.open(tmp_path / "flock.gif") as image:
        assert image.n_frames == solution.motion.n_frames


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
