import math
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import FileFormatError, FlockkitError, ValidationError
from flockkit.testing import strategies as fst


def line_motion(frames=5, agents=3, dims=2, dt=0.5):
    t = np.arange(frames, dtype=float)[:, None, None]
    positions = np.zeros((frames, agents, dims)) + t * np.eye(dims)[0] + np.arange(agents)[None, :, None]
    return flockkit.Motion(positions=positions, dt=dt)


@pytest.mark.parametrize(
    "positions, dt, field",
    [
        (np.zeros((4, 3)), 0.1, "Motion.positions"),
        (np.zeros((4, 3, 4)), 0.1, "Motion.positions"),
        (np.zeros((0, 3, 2)), 0.1, "Motion.positions"),
        (np.zeros((4, 0, 2)), 0.1, "Motion.positions"),
        (np.full((2, 2, 2), np.nan), 0.1, "Motion.positions"),
        (np.full((2, 2, 2), np.inf), 0.1, "Motion.positions"),
        ("abc", 0.1, "Motion.positions"),
        (np.zeros((2, 2, 2)), 0.0, "Motion.dt"),
        (np.zeros((2, 2, 2)), -1.0, "Motion.dt"),
        (np.zeros((2, 2, 2)), float("nan"), "Motion.dt"),
        (np.zeros((2, 2, 2)), "fast", "Motion.dt"),
    ],
)
def test_motion_rejects_bad_input_naming_the_field(positions, dt, field):
    with pytest.raises(ValidationError) as info:
        flockkit.Motion(positions=positions, dt=dt)
    assert field in str(info.value)
    assert isinstance(info.value, ValueError) and isinstance(info.value, FlockkitError)


def test_motion_channels_are_validated():
    with pytest.raises(ValidationError, match=r"channels\['wander'\]"):
        flockkit.Motion(positions=np.zeros((3, 2, 2)), dt=1, channels={"wander": np.zeros((3, 2, 3))})
    with pytest.raises(ValidationError, match="identifiers"):
        flockkit.Motion(positions=np.zeros((3, 2, 2)), dt=1, channels={"not valid": np.zeros((3, 2, 2))})
    with pytest.raises(ValidationError, match="finite"):
        flockkit.Motion(positions=np.zeros((3, 2, 2)), dt=1, channels={"w": np.full((3, 2, 2), np.nan)})


def test_motion_arrays_are_read_only_float64_copies():
    source = np.zeros((3, 2, 2), dtype=np.int32)
    motion = flockkit.Motion(positions=source, dt=1, channels={"w": source})
    source[0, 0, 0] = 7
    assert motion.positions.dtype == np.float64 and motion.positions[0, 0, 0] == 0
    with pytest.raises(ValueError):
        motion.positions[0, 0, 0] = 1
    with pytest.raises(ValueError):
        motion.channels["w"][0, 0, 0] = 1
    with pytest.raises(TypeError):
        motion.channels["x"] = source
    with pytest.raises(AttributeError):
        motion.dt = 2.0


def test_motion_properties_and_velocities():
    motion = line_motion(frames=5, agents=3, dims=3, dt=0.5)
    assert (motion.n_frames, motion.n_agents, motion.dims, motion.duration) == (5, 3, 3, 2.0)
    velocities = motion.velocities()
    assert velocities.shape == (5, 3, 3)
    np.testing.assert_allclose(velocities[..., 0], 2.0)
    np.testing.assert_allclose(motion.center_of_mass()[:, 1], 1.0)
    single = flockkit.Motion(positions=np.ones((1, 2, 2)), dt=1)
    assert not single.velocities().any() and single.duration == 0


def test_velocity_convention_forward_difference_then_arrival():
    positions = np.array([0.0, 1.0, 3.0, 6.0])[:, None, None] * np.array([1.0, 0.0])
    motion = flockkit.Motion(positions=positions, dt=1.0)
    np.testing.assert_array_equal(motion.velocities()[:, 0, 0], [1.0, 2.0, 3.0, 3.0])
    np.testing.assert_array_equal(motion.state(1).velocities[0], [2.0, 0.0])
    np.testing.assert_array_equal(motion.state(-1).velocities[0], [3.0, 0.0])


def test_state_and_configuration_access():
    motion = flockkit.Motion(
        positions=np.random.default_rng(0).random((6, 4, 2)), dt=0.1, channels={"wander": np.ones((6, 4, 2))}
    )
    assert motion.state(-2) == motion.state(4)
    np.testing.assert_array_equal(motion.configuration(2).velocities, motion.velocities()[2])
    np.testing.assert_array_equal(motion.state(3).extra["wander"], np.ones((4, 2)))
    for bad in (6, -7, 1.5, True):
        with pytest.raises(ValidationError):
            motion.state(bad)


def test_slicing():
    motion = line_motion(frames=10)
    part = motion[2:6]
    assert part.n_frames == 4 and part.dt == motion.dt
    np.testing.assert_array_equal(part.positions, motion.positions[2:6])
    strided = motion[::3]
    assert strided.n_frames == 4 and strided.dt == pytest.approx(3 * motion.dt)
    with pytest.raises(ValidationError):
        motion[5:5]
    with pytest.raises(ValidationError):
        motion[::-1]
    with pytest.raises(TypeError):
        motion[3]


@settings(max_examples=25, deadline=None)
@given(fst.motions(max_frames=6, max_agents=4, channels=["wander"]))
def test_save_load_round_trip(tmp_path_factory, motion):
    path = tmp_path_factory.mktemp("m") / "motion.npz"
    motion.save(path)
    assert flockkit.Motion.load(path) == motion
    assert [p.name for p in path.parent.iterdir()] == ["motion.npz"]  # no temporary left behind


def test_load_rejects_broken_files(tmp_path):
    good = tmp_path / "good.npz"
    line_motion().save(good)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file at all")
    plain = tmp_path / "plain.npz"
    np.savez(plain, positions=np.zeros((2, 2, 2)))
    single = tmp_path / "single.npz"
    with open(single, "wb") as handle:
        np.save(handle, np.zeros((2, 2, 2)))
    for path in (truncated, garbage, plain, single):
        with pytest.raises(FileFormatError) as info:
            flockkit.Motion.load(path)
        assert str(path) in str(info.value)
    with pytest.raises(FileNotFoundError):
        flockkit.Motion.load(tmp_path / "missing.npz")


def _rewrite_metadata(source, target, **changes):
    import json

    with np.load(source) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays["__metadata__"].tobytes())
    header.update(changes)
    arrays["__metadata__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(target, **arrays)


def test_load_rejects_other_versions_and_kinds(tmp_path):
    good = tmp_path / "good.npz"
    line_motion().save(good)
    _rewrite_metadata(good, tmp_path / "v99.npz", version=99)
    with pytest.raises(FileFormatError, match="version 99"):
        flockkit.Motion.load(tmp_path / "v99.npz")
    _rewrite_metadata(good, tmp_path / "graph.npz", format="graph")
    with pytest.raises(FileFormatError, match="'graph'"):
        flockkit.Motion.load(tmp_path / "graph.npz")
    _rewrite_metadata(good, tmp_path / "baddt.npz", dt=-1)
    with pytest.raises(FileFormatError, match="Motion.dt"):
        flockkit.Motion.load(tmp_path / "baddt.npz")


def test_saved_file_needs_no_pickle(tmp_path):
    path = tmp_path / "m.npz"
    line_motion().save(path)
    with zipfile.ZipFile(path) as archive:
        assert sorted(archive.namelist()) == ["__metadata__.npy", "positions.npy"]
    with np.load(path, allow_pickle=False) as npz:
        assert npz["positions"].dtype == np.float64


def test_failed_save_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "m.npz"

    def explode(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(np, "savez_compressed", explode)
    with pytest.raises(RuntimeError):
        line_motion().save(path)
    assert list(tmp_path.iterdir()) == []


def test_state_validation():
    with pytest.raises(ValidationError, match="State.velocities"):
        flockkit.State(positions=np.zeros((3, 2)), velocities=np.zeros((3, 3)))
    with pytest.raises(ValidationError, match=r"State.extra\['wander'\]"):
        flockkit.State(positions=np.zeros((3, 2)), velocities=np.zeros((3, 2)), extra={"wander": np.zeros((2, 2))})
    with pytest.raises(ValidationError, match="Configuration.positions"):
        flockkit.Configuration(positions=np.zeros((3, 1)), velocities=np.zeros((3, 1)))


def rotation(dims, angles):
    if dims == 2:
        c, s = math.cos(angles[0]), math.sin(angles[0])
        return np.array([[c, -s], [s, c]])
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("zyx", angles).as_matrix()


@settings(max_examples=60, deadline=None)
@given(
    fst.configurations(min_agents=2, max_agents=8, max_coordinate=10.0, max_speed=3.0),
    st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3),
    st.lists(st.floats(-50, 50), min_size=3, max_size=3),
)
def test_configuration_frame_is_invariant_to_rigid_motion_about_up(config, angles, shift):
    mean_velocity = config.velocities.mean(axis=0)
    speeds = np.linalg.norm(config.velocities, axis=1).mean()
    if config.dims == 3:
        angles = [angles[0], 0.0, 0.0]  # rotations about the up axis keep the 3D frame's roll
        horizontal = np.linalg.norm(mean_velocity[:2])
        if horizontal < 1e-3 * max(speeds, 1e-12):
            return
    if np.linalg.norm(mean_velocity) <= 1e-3 * max(speeds, 1e-12):
        return
    d = config.dims
    turn, offset = rotation(d, angles), np.array(shift[:d])
    moved = flockkit.Configuration(positions=config.positions @ turn.T + offset, velocities=config.velocities @ turn.T)
    frame, moved_frame = config.frame(), moved.frame()
    local = frame.to_local(config.positions)
    np.testing.assert_allclose(moved_frame.to_local(moved.positions), local, atol=1e-7)
    np.testing.assert_allclose(local.mean(axis=0), 0, atol=1e-7)
    heading = frame.vectors_to_local(mean_velocity)
    assert heading[0] > 0 and np.allclose(heading[1:], 0, atol=1e-7 * max(1, np.linalg.norm(mean_velocity)))
    np.testing.assert_allclose(frame.to_world(local), config.positions, atol=1e-7)


@settings(max_examples=40, deadline=None)
@given(fst.configurations(min_agents=1, max_agents=6))
def test_frame_is_always_a_proper_rotation(config):
    axes = config.frame().axes
    np.testing.assert_allclose(axes @ axes.T, np.eye(config.dims), atol=1e-9)
    assert np.linalg.det(axes) == pytest.approx(1.0)


def test_frame_fallbacks():
    still = flockkit.Configuration(positions=[[0.0, 0.0], [2.0, 0.0]], velocities=[[1.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_allclose(still.frame().axes, np.eye(2))
    up = flockkit.Configuration(positions=np.zeros((2, 3)), velocities=[[0, 0, 1.0], [0, 0, 1.0]])
    axes = up.frame().axes
    np.testing.assert_allclose(axes[0], [0, 0, 1])
    assert np.linalg.det(axes) == pytest.approx(1.0)
    level = flockkit.Configuration(positions=np.zeros((1, 3)), velocities=[[1.0, 0, 0]])
    np.testing.assert_allclose(level.frame().axes, np.eye(3), atol=1e-12)
    y_up = level.frame(up=(0, 1, 0)).axes
    np.testing.assert_allclose(y_up[2], [0, 1, 0], atol=1e-12)
    with pytest.raises(ValidationError, match="up"):
        level.frame(up=(0, 0, 0))


@settings(max_examples=30, deadline=None)
@given(st.lists(fst.configurations(min_agents=3, max_agents=3, dims=3), min_size=1, max_size=6))
def test_heading_axes_of_many_equals_each_frame(configs):
    still = flockkit.Configuration(positions=np.zeros((3, 3)), velocities=[[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 0]])
    upward = flockkit.Configuration(positions=np.zeros((3, 3)), velocities=np.tile([0, 0, 2.0], (3, 1)))
    configs = [*configs, still, upward]  # both fallbacks in the batch
    many = flockkit.heading_axes(np.stack([c.velocities for c in configs]))
    np.testing.assert_array_equal(many, np.stack([c.frame().axes for c in configs]))
    np.testing.assert_allclose(many[-2], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(many[-1][0], [0, 0, 1])


def test_heading_axes_refuses_other_shapes():
    with pytest.raises(ValidationError, match="heading_axes"):
        flockkit.heading_axes(np.zeros((4, 3, 4)))
