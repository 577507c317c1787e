import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import FileFormatError, ValidationError
from flockkit.io import fill_gaps, read_long, read_npy, read_wide
from flockkit.testing import strategies as fst


def write_long(path, motion, delimiter=","):
    rows = [
        delimiter.join(str(v) for v in (t * 10, agent + 1, *motion.positions[t, agent]))
        for t in range(motion.n_frames)
        for agent in range(motion.n_agents)
    ]
    path.write_text("frame,agent,x,y\n" + "\n".join(rows) + "\n")


def test_long_table_round_trip(tmp_path):
    motion = flockkit.simulate(n_agents=4, steps=12, seed=1)
    write_long(tmp_path / "long.csv", motion)
    read = read_long(tmp_path / "long.csv", dt=0.1)
    np.testing.assert_allclose(read.positions, motion.positions, rtol=1e-12)
    assert read.dt == 0.1


def test_wide_table_3d_with_header_and_tabs(tmp_path):
    motion = flockkit.simulate(n_agents=3, steps=6, dims=3, seed=2)
    lines = ["frame\tx1\ty1\tz1\tx2\ty2\tz2\tx3\ty3\tz3"]
    lines += ["\t".join(str(v) for v in (t, *motion.positions[t].ravel())) for t in range(motion.n_frames)]
    (tmp_path / "wide.tsv").write_text("\n".join(lines))
    read = read_wide(tmp_path / "wide.tsv", fps=10, dims=3)
    np.testing.assert_allclose(read.positions, motion.positions, rtol=1e-12)


def test_sticklebacks(shared_data):
    path = shared_data / "sticklebacks-5" / "ground_truth.csv"
    motion = read_wide(path, fps=15)
    table = np.loadtxt(path, delimiter=",")
    np.testing.assert_array_equal(motion.positions, table[:, 1:].reshape(-1, 5, 2))
    assert motion.dt == pytest.approx(1 / 15)
    upright = read_wide(path, fps=15, image_height=720)  # pixels of a 1280 x 720 video, y down
    np.testing.assert_array_equal(upright.positions[..., 0], motion.positions[..., 0])
    np.testing.assert_array_equal(upright.positions[..., 1], 720 - motion.positions[..., 1])
    with pytest.raises(ValidationError, match="image_height"):
        read_wide(path, fps=15, image_height=-1)


def test_trajectorytools_nan_handling(shared_data):
    folder = shared_data / "trajectorytools-fish"
    with pytest.raises(ValidationError) as info:
        read_npy(folder / "fish8_positions.npy", fps=28)
    assert "agent 1: frames 239..261" in str(info.value) and "fish8_positions.npy" in str(info.value)
    raw = np.load(folder / "fish8_positions.npy")
    motion = read_npy(folder / "fish8_positions.npy", fps=28, max_gap=30)
    known = ~np.isnan(raw)
    np.testing.assert_array_equal(motion.positions[known], raw[known])  # known values untouched
    assert np.isfinite(motion.positions).all()
    assert read_npy(folder / "fish15_positions.npy", fps=32).n_agents == 15
    crowd = read_npy(folder / "test_trajectories.npy", fps=32, max_gap=60)
    assert crowd.positions.shape == (300, 100, 2)


def test_pedestrians_select_a_window(shared_data):
    path = shared_data / "eth-ucy-pedestrians" / "biwi_eth.txt"
    with pytest.raises(ValidationError, match=r"frames \d+\.\.\d+"):
        read_long(path, fps=2.5)
    table = np.loadtxt(path)
    frames_of = {a: set(table[table[:, 1] == a, 0]) for a in (2.0, 3.0)}
    both = sorted(frames_of[2.0] & frames_of[3.0])
    step = int(np.gcd.reduce(np.diff(np.unique(table[:, 0])).astype(int)))
    start = int((both[0] - table[:, 0].min()) // step)  # the frame slot of the first shared frame
    motion = read_long(path, fps=2.5, agents=[2.0, 3.0], frames=slice(start, start + 3), max_gap=0)
    assert motion.positions.shape == (3, 2, 2)


def test_fill_gaps_policy():
    positions = np.zeros((8, 2, 2))
    positions[:, 0, 0] = np.arange(8.0)
    positions[2:4, 0] = np.nan  # interior: linear
    positions[:2, 1] = np.nan  # leading: hold the nearest
    positions[1:, 1, 1] = np.arange(7.0)
    positions[:2, 1] = np.nan
    filled = fill_gaps(positions, max_gap=2)
    np.testing.assert_allclose(filled[:, 0, 0], np.arange(8.0))
    np.testing.assert_allclose(filled[:2, 1], [filled[2, 1], filled[2, 1]])
    with pytest.raises(ValidationError, match=r"agent 0: frames 2\.\.3"):
        fill_gaps(positions, max_gap=1)
    with pytest.raises(ValidationError, match="agent 1: never seen"):
        fill_gaps(np.where(np.arange(2)[None, :, None] == 1, np.nan, 0.0) * np.ones((3, 2, 2)), max_gap=5)


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_fill_gaps_keeps_known_values(data):
    motion = data.draw(fst.motions(min_frames=3, max_frames=15, max_agents=4))
    positions = np.array(motion.positions)
    holes = data.draw(
        st.lists(st.tuples(st.integers(0, motion.n_frames - 1), st.integers(0, motion.n_agents - 1)), max_size=6)
    )
    for t, agent in holes:
        positions[t, agent] = np.nan
    if np.isnan(positions).all(axis=(0, 2)).any():
        with pytest.raises(ValidationError, match="never seen"):
            fill_gaps(positions, max_gap=motion.n_frames)
        return
    filled = fill_gaps(positions, max_gap=motion.n_frames)
    known = ~np.isnan(positions)
    np.testing.assert_array_equal(filled[known], positions[known])
    assert np.isfinite(filled).all()


@pytest.mark.parametrize(
    "content, expected",
    [
        ("1,2,3\n4,5\n", "line 2"),
        ("frame,x\n1,abc\n2,3\n", "line 2"),
        ("0,1,2,3\n", "multiple of dims"),
        ("", "no data"),
    ],
)
def test_bad_tables(tmp_path, content, expected):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(FileFormatError, match=expected):
        read_wide(path, dt=0.1)


def test_rate_must_be_given_once(tmp_path):
    with pytest.raises(ValidationError, match="exactly one of dt"):
        read_wide(tmp_path / "any.csv")
    with pytest.raises(ValidationError, match="exactly one of dt"):
        read_npy(tmp_path / "any.npy", dt=0.1, fps=10)
    with pytest.raises(FileNotFoundError):
        read_npy(tmp_path / "missing.npy", fps=10)


def test_npy_refuses_other_arrays(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros((4, 2)))
    with pytest.raises(FileFormatError, match=r"\(T, N, D\)"):
        read_npy(tmp_path / "flat.npy", fps=10)
    np.save(tmp_path / "objects.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(FileFormatError):
        read_npy(tmp_path / "objects.npy", fps=10)


def _obj_frame(path, points, faces, *, extra=""):
    vertices = "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}{extra}\n" for x, y, z in points)
    path.write_text("# frame\no thing\n" + vertices + "".join("f " + " ".join(f"{i + 1}//{i + 1}" for i in f) + "\n"
                                                              for f in faces))  # fmt: skip


def test_obj_frames_after_the_first_equal_a_line_by_line_reading(tmp_path):
    """Later frames with the first frame's face lines are parsed by numpy at once; what they give
    is what the line-by-line parser gives, vertex colours and w coordinates included."""
    from flockkit.io import obj

    rng = np.random.default_rng(7)
    points, faces = rng.normal(size=(50, 3)), rng.integers(0, 50, (60, 3))
    for t, extra in enumerate(("", " 1.0", " 0.5 0.25 1", "")):  # plain, w, colours, plain
        _obj_frame(tmp_path / f"frame{t}.obj", points + 0.1 * t, faces, extra=extra)
    positions, found_faces, _ = obj.read_sequence(str(tmp_path))
    for t in range(4):
        careful, careful_faces = obj._parse_obj(tmp_path / f"frame{t}.obj", (tmp_path / f"frame{t}.obj").read_text())
        np.testing.assert_array_equal(positions[t], careful)
        np.testing.assert_array_equal(found_faces, careful_faces)
    np.testing.assert_array_equal(positions[3], points + 0.1 * 3)  # repr round-trips a float exactly


def test_a_bad_vertex_in_a_later_obj_frame_is_named_by_its_line(tmp_path):
    from flockkit.io import obj

    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    for t in range(3):
        _obj_frame(tmp_path / f"frame{t}.obj", quad + t, [[0, 1, 2, 3]])
    bad = tmp_path / "frame2.obj"
    bad.write_text(bad.read_text().replace("v 2.0 3.0 2.0", "v 2.0 x 2.0"))
    with pytest.raises(FileFormatError, match=r"frame2.obj, line 6: not an OBJ vertex"):
        obj.read_sequence(str(tmp_path))
    bad.write_text(bad.read_text().replace("v 2.0 x 2.0", "v 2.0 nan 2.0"))
    with pytest.raises(FileFormatError, match="frame2.obj: vertices must have finite coordinates"):
        obj.read_sequence(str(tmp_path))
