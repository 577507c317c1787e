import json

import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def motion(request):
    return flockkit.simulate(n_agents=6, steps=25, dims=request.param, seed=8)


def test_csv_round_trips_through_the_long_reader(motion, tmp_path):
    flockkit.io.export(motion, tmp_path / "flock.csv")
    back = flockkit.io.read_long(tmp_path / "flock.csv", dt=motion.dt, dims=motion.dims)
    np.testing.assert_array_equal(back.positions, motion.positions)


def test_json_holds_the_positions(motion, tmp_path):
    flockkit.io.export(motion, tmp_path / "flock.json")
    document = json.loads((tmp_path / "flock.json").read_text())
    assert document["format"] == "flockkit-motion" and document["dt"] == motion.dt
    np.testing.assert_array_equal(np.array(document["positions"]), motion.positions)


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_has_a_time_sample_per_frame_facing_the_velocity(motion, tmp_path, suffix):
    pytest.importorskip("pxr", reason="usd-core (flockkit[usd]) is not installed")
    from pxr import Gf, Usd, UsdGeom

    path = tmp_path / f"flock{suffix}"
    flockkit.io.export(motion, path)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1 / motion.dt)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, motion.n_frames - 1)
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Flock/Agents"))
    assert instancer.GetPositionsAttr().GetTimeSamples() == list(range(motion.n_frames))
    velocities = motion.velocities()
    for frame in (0, 11, motion.n_frames - 1):
        points = np.array(instancer.GetPositionsAttr().Get(Usd.TimeCode(frame)))
        np.testing.assert_allclose(points[:, : motion.dims], motion.positions[frame], atol=1e-5)
        for agent, q in enumerate(instancer.GetOrientationsAttr().Get(Usd.TimeCode(frame))):
            facing = np.array(Gf.Rotation(Gf.Quatd(q)).TransformDir(Gf.Vec3d(1, 0, 0)))
            heading = np.zeros(3)
            heading[: motion.dims] = velocities[frame, agent] / np.linalg.norm(velocities[frame, agent])
            np.testing.assert_allclose(facing, heading, atol=2e-3)  # half-precision quaternions


def test_unknown_extensions_are_refused_and_nothing_is_written(tmp_path):
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    with pytest.raises(ValidationError, match="unknown export extension"):
        flockkit.io.export(motion, tmp_path / "flock.fbx")
    assert list(tmp_path.iterdir()) == []


def test_usd_without_usd_core_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pxr", None)  # as if usd-core were not installed
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    with pytest.raises(flockkit.errors.MissingDependencyError, match=r"flockkit\[usd\]"):
        flockkit.io.export(motion, tmp_path / "flock.usdc")
    assert list(tmp_path.iterdir()) == []
