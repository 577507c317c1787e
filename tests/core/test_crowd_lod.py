"""Levels of detail: far agents refreshed every 2^level frames, staggered, their records held between."""

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool
from flockkit.crowd.runtime import MAX_LOD
from flockkit.errors import ValidationError
from flockkit.testing import inputs

N = 24


def crowd_in_motion(root_motion=None):
    """Half the agents dilate into a Stopped stream (offsets moving every frame), the rest read a
    Running stream steadily."""
    clip = inputs.strider(speed=1.0, turn=0.2) if root_motion else inputs.walker()
    if root_motion:
        clip = flockkit.crowd.extract_root_motion(clip)
    play = lambda rate: flockkit.get("controller", "clip", clip=clip, rate=rate)  # noqa: E731
    pool = StreamPool([Stream(controller=play(1.0), history=40),
                       Stream(controller=play(0.8), history=40, default="Stopped")], fps=30)  # fmt: skip
    crowd = Crowd(pool, n_agents=N, clusters={"body": 0}, seed=5, root_motion=root_motion)
    crowd.transition_to_streamed(np.arange(0, N, 2), "body", 1, blend_time=0.2, time_to_dilate=1.5)
    return crowd


def test_far_agents_are_held_between_their_refreshes_and_near_ones_are_exact():
    crowd, twin = crowd_in_motion(), crowd_in_motion()
    far = np.arange(N // 2, N)
    crowd.set_lod(far, 2)  # every 4th frame
    for _ in range(40):
        before = crowd.instance_buffer().copy()
        crowd.update()
        twin.update()
        now = crowd.instance_buffer()
        due = crowd.due()
        np.testing.assert_array_equal(due[: N // 2], True)
        np.testing.assert_array_equal(due[far], (crowd.frame + far) % 4 == 0)  # staggered
        np.testing.assert_array_equal(now[: N // 2], twin.instance_buffer()[: N // 2])  # near: exact
        held = far[~due[far]]
        np.testing.assert_array_equal(now[held], before[held])  # far, not due: held
        np.testing.assert_array_equal(crowd.entries(np.arange(N // 2)), twin.entries(np.arange(N // 2)))
    dilating = far[far % 2 == 0]
    assert np.all(crowd.instance_buffer()["offset"][dilating, 0] > 0)  # far parts did move, in steps
    # a far part moves by its rate times the frames since it last moved, so it arrives as a near one does
    for _ in range(60):
        crowd.update()
        twin.update()
    np.testing.assert_array_equal(crowd.dilation_targets("body"), twin.dilation_targets("body"))
    assert np.all(np.isnan(crowd.dilation_targets("body")))
    np.testing.assert_allclose(crowd.offsets("body"), twin.offsets("body"), atol=1e-4)


def test_a_new_level_takes_effect_at_the_next_update():
    crowd = crowd_in_motion()
    far = np.arange(0, N, 2)  # the dilating ones
    crowd.set_lod(far, 3)
    for _ in range(3):
        crowd.update()
    assert crowd.lod[far].tolist() == [3] * len(far) and crowd.lod[1] == 0
    crowd.set_lod(far, 0)
    before = crowd.offsets("body")[far]  # of the stream blended to
    crowd.update()
    assert crowd.due()[far].all()
    moved = crowd.offsets("body")[far] - before
    assert np.all(moved > 0)  # every one moves at once, by the frames it had waited
    crowd.set_lod(np.arange(N), 1)
    crowd.update()
    assert crowd.due().sum() == N // 2  # staggered: half the agents are due each frame


def test_refresh_rewrites_only_the_due_agents_poses():
    crowd = crowd_in_motion()
    crowd.set_lod(np.arange(N), np.arange(N) % (MAX_LOD + 1))
    buffer = np.zeros((N, crowd.skeletons[0].n_joints, 12), np.float32)
    crowd.update()
    written = crowd.refresh(buffer, "body")
    np.testing.assert_array_equal(written, np.flatnonzero(crowd.due()))
    for _ in range(9):
        held = buffer.copy()
        crowd.update()
        written = crowd.refresh(buffer, "body")
        due = crowd.due()
        np.testing.assert_array_equal(buffer[due], crowd.entries(np.flatnonzero(due), "body"))
        np.testing.assert_array_equal(buffer[~due], held[~due])
        assert len(written) < N  # levels above 0 skip some agents every frame
    with pytest.raises(ValidationError, match="out must"):
        crowd.refresh(buffer[:3], "body")


def test_far_roots_move_on_their_frames_by_what_they_read_since():
    crowd, twin = crowd_in_motion("body"), crowd_in_motion("body")
    steady = np.arange(1, N, 2)  # not blending: their steps are the same motion, added up
    crowd.set_lod(steady, 2)
    for _ in range(17):  # agents 3, 7, 11, ... are refreshed on frame 17
        crowd.update()
        twin.update()
    synced = steady[(crowd.frame + steady) % 4 == 0]
    assert len(synced)
    np.testing.assert_allclose(crowd.roots()[synced], twin.roots()[synced], atol=1e-9)
    lagging = steady[(crowd.frame + steady) % 4 != 0]
    assert not np.allclose(crowd.roots()[lagging], twin.roots()[lagging])


def test_levels_from_a_camera_follow_the_distance_bands():
    crowd = crowd_in_motion()
    crowd.placement[:, 0, 3] = np.arange(N) * 10.0  # agents along x, 10 apart
    levels = crowd.lod_from_camera((0.0, 0.0, 0.0), bands=(25.0, 75.0, 150.0))
    expected = np.searchsorted([25.0, 75.0, 150.0], np.arange(N) * 10.0, side="right")
    np.testing.assert_array_equal(levels, expected)
    np.testing.assert_array_equal(crowd.lod, expected)
    assert levels[0] == 0 and levels[-1] == MAX_LOD


def test_bad_levels_are_refused_by_name():
    crowd = crowd_in_motion()
    for level, message in (
        (MAX_LOD + 1, r"lod: levels must lie in 0..3"),
        (-1, r"lod: levels must lie in 0..3"),
        (1.5, r"lod: levels must be integers"),
        ([1, 2], r"lod: levels must be integers 0..3, one for all agents or one each"),
        ("far", r"lod: levels must be integers"),
    ):
        with pytest.raises(ValidationError, match=message):
            crowd.set_lod([0, 1, 2], level)
    with pytest.raises(ValidationError, match="unknown agent id 99"):
        crowd.set_lod([99], 1)
    for camera in ((0, 0), (0, np.nan, 0), "here"):
        with pytest.raises(ValidationError, match="camera must be a finite world point"):
            crowd.lod_from_camera(camera, bands=(10,))
    for bands in ((), (10, 5), (0,), (1, 2, 3, 4), (np.inf,), "near"):
        with pytest.raises(ValidationError, match="bands must be 1 to 3 increasing positive distances"):
            crowd.lod_from_camera((0, 0, 0), bands=bands)
    assert not crowd.lod.any()  # refused calls change nothing
