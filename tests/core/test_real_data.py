"""The foundation on real captured motion: five sticklebacks, 301 frames at 15 fps, in pixels."""

import numpy as np
import pytest

import flockkit


@pytest.fixture
def sticklebacks(shared_data):
    table = np.loadtxt(shared_data / "sticklebacks-5" / "ground_truth.csv", delimiter=",")
    return flockkit.Motion(positions=table[:, 1:].reshape(-1, 5, 2), dt=1 / 15)


def test_capture_becomes_a_motion(sticklebacks, tmp_path):
    assert (sticklebacks.n_frames, sticklebacks.n_agents, sticklebacks.dims) == (301, 5, 2)
    assert sticklebacks.duration == pytest.approx(20.0)
    sticklebacks.save(tmp_path / "fish.npz")
    assert flockkit.Motion.load(tmp_path / "fish.npz") == sticklebacks


def test_configuration_frames_follow_the_school(sticklebacks):
    for t in range(sticklebacks.n_frames):
        config = sticklebacks.configuration(t)
        frame = config.frame()
        np.testing.assert_allclose(frame.axes @ frame.axes.T, np.eye(2), atol=1e-12)
        mean_velocity = config.velocities.mean(axis=0)
        if np.linalg.norm(mean_velocity) > 0:  # rows 0 and 1 of the capture are identical
            heading = frame.vectors_to_local(mean_velocity)
            assert heading[0] > 0 and abs(heading[1]) < 1e-9 * np.linalg.norm(mean_velocity)


def test_boids_scores_real_fish(sticklebacks):
    """Plausibility inference runs on motion no model made: finite, one value per frame."""
    model = flockkit.get(
        "behavior", "boids", dt=1 / 15, perception_radius=300.0, separation_radius=40.0, target_speed=150.0
    )
    values = model.log_plausibility(sticklebacks)
    assert values.shape == (301,) and np.all(np.isfinite(values))
    shaken = flockkit.Motion(
        positions=sticklebacks.positions + np.random.default_rng(0).normal(0, 15, sticklebacks.positions.shape),
        dt=sticklebacks.dt,
    )
    assert values.sum() > model.log_plausibility(shaken).sum()


def test_missing_data_skips_or_fails_as_asked(tmp_path, monkeypatch):
    from ..conftest import require_folder

    missing = tmp_path / "nowhere"
    monkeypatch.delenv("FLOCKKIT_REQUIRE_SHARED_DATA", raising=False)
    with pytest.raises(pytest.skip.Exception, match="not found"):
        require_folder(missing)
    monkeypatch.setenv("FLOCKKIT_REQUIRE_SHARED_DATA", "1")
    with pytest.raises(pytest.fail.Exception, match="FLOCKKIT_REQUIRE_SHARED_DATA=1"):
        require_folder(missing)
    assert require_folder(tmp_path) == tmp_path
