"""The built-in controllers: clip, blend, mask and graph-walk (paper 003, section 3.4)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import flockkit
from flockkit.errors import ValidationError
from flockkit.io import read_clips
from flockkit.testing import inputs

WALKER = inputs.walker()  # 2 s cycle at 30 fps, steps at 0.5 s and 1.5 s


def get(name, **params):
    return flockkit.get("controller", name, **params)


def angle(a, b):
    """Angles (radians) between unit quaternions."""
    return 2 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=-1)), 0, 1))


def test_clip_loops_or_holds_at_its_rate_and_maps_events_to_stream_time():
    looped = get("clip", clip=WALKER, rate=2.0, start=0.25)
    # stream time t plays clip time 0.25 + 2 t, modulo the 2 s period
    np.testing.assert_allclose(looped.pose([1.0]).rotations, WALKER.sample([0.25]).rotations, atol=1e-12)
    np.testing.assert_allclose(looped.pose([0.3]).rotations, WALKER.sample([0.85]).rotations, atol=1e-12)
    steps = looped.events(0.0, 2.0)
    np.testing.assert_allclose([e.time for e in steps], [0.125, 0.625, 1.125, 1.625])  # (0.5 - 0.25) / 2, ...
    once = get("clip", clip=WALKER, loop=False)
    np.testing.assert_array_equal(once.pose([5.0]).rotations, WALKER.sample([WALKER.duration]).rotations)
    assert [e.time for e in once.events(0.0, 10.0)] == [0.5, 1.5]
    with pytest.raises(ValidationError, match="rate"):
        get("clip", clip=WALKER, rate=0)
    with pytest.raises(ValidationError, match="SkeletalClip"):
        get("clip", clip="walk.bvh")


def test_blend_follows_equation_2_with_a_keyframed_weight():
    a, b = get("clip", clip=WALKER), get("clip", clip=WALKER, start=0.7)
    blend = get("blend", a=a, b=b, weight=[[0.0, 0.0], [1.0, 1.0]])
    t = np.array([0.0, 0.25, 0.5, 1.0, 1.5])
    pose, pa, pb = blend.pose(t), a.pose(t), b.pose(t)
    np.testing.assert_allclose(pose.rotations[0], pa.rotations[0], atol=1e-12)  # s = 0: a
    np.testing.assert_allclose(pose.rotations[3:], pb.rotations[3:], atol=1e-12)  # s = 1 (and held): b
    s = 0.25
    np.testing.assert_allclose(pose.translations[1], pa.translations[1] + s * (pb.translations[1] - pa.translations[1]))
    # on the sphere, between the two: the angles to a and to b add up to the angle between them
    between = angle(pa.rotations[2], pb.rotations[2])
    np.testing.assert_allclose(
        angle(pose.rotations[2], pa.rotations[2]) + angle(pose.rotations[2], pb.rotations[2]), between, atol=1e-9
    )
    assert len(blend.events(0.0, 2.0)) == 4  # both children's steps
    other = get("clip", clip=inputs.random_clip(4))
    with pytest.raises(ValidationError, match="does not match"):
        get("blend", a=a, b=other)
    with pytest.raises(ValidationError, match=r"\[0, 1\]"):
        get("blend", a=a, b=b, weight=1.5)
    with pytest.raises(ValidationError, match="increase"):
        get("blend", a=a, b=b, weight=[[1.0, 0.0], [0.5, 1.0]])


def test_mask_takes_each_joint_from_the_child_that_holds_it():
    slow, fast = get("clip", clip=WALKER), get("clip", clip=WALKER, rate=3.0)
    mixed = get("mask", children=[slow, fast], masks=[~WALKER.skeleton.descendants("leg.L"), "leg.L"])
    t = np.linspace(0, 2, 9)
    pose = mixed.pose(t)
    legs = WALKER.skeleton.descendants("leg.L")
    np.testing.assert_array_equal(pose.rotations[:, legs], fast.pose(t).rotations[:, legs])
    np.testing.assert_array_equal(pose.rotations[:, ~legs], slow.pose(t).rotations[:, ~legs])
    with pytest.raises(ValidationError, match="joint 'leg.L' is held by 2 masks"):
        get("mask", children=[slow, fast], masks=["hips", "leg.L"])
    with pytest.raises(ValidationError, match="joint 'leg.L' is held by 0 masks"):
        get("mask", children=[slow, fast], masks=[~legs, np.zeros(len(legs), dtype=int)])
    with pytest.raises(ValidationError, match="no joint 'tail'"):
        get("mask", children=[slow, fast], masks=[~legs, "tail"])


def test_graph_walk_is_endless_smooth_and_deterministic(shared_data):
    idle = read_clips(shared_data / "robot-expressive-gltf" / "RobotExpressive.glb")["Idle"]
    stream = get("graph-walk", clip=idle, seed=5)
    assert len(stream.graph.transitions) >= 5
    t = np.arange(0, 60, 1 / idle.fps)  # a minute of a 3.3 s clip
    pose = stream.pose(t)
    # it takes transitions: not the clip looped (frames played are not consecutive everywhere)
    into = flockkit.graphs.blended_frames(
        stream.graph, flockkit.Walk(start=stream._walk["start"], edges=stream._walk["edges"])
    )[0]
    jumps = np.count_nonzero(np.diff(into[: len(t)]) != 1)
    assert jumps >= 5
    # smooth: transitions are blended, so no step between frames is much beyond the clip's own
    # largest (7 degrees), while cutting straight to the frames played would jump 40 degrees
    source_step = angle(idle.rotations[1:], idle.rotations[:-1]).max()
    cut = idle.rotations[into[: len(t)]]
    assert angle(pose.rotations[1:], pose.rotations[:-1]).max() <= 2 * source_step
    assert angle(cut[1:], cut[:-1]).max() > 4 * source_step
    again = get("graph-walk", clip=idle, seed=5)
    np.testing.assert_array_equal(again.pose(t[::-1]).rotations[::-1], pose.rotations)  # a function of time
    assert not np.array_equal(get("graph-walk", clip=idle, seed=6).pose(t).rotations, pose.rotations)


def test_quaternion_helpers_agree_with_scipy():
    rng = np.random.default_rng(0)
    a, b = Rotation.random(20, random_state=1), Rotation.random(20, random_state=2)
    np.testing.assert_allclose(
        np.abs(np.sum(flockkit.rigid.quaternion_product(a.as_quat(), b.as_quat()) * (a * b).as_quat(), axis=1)),
        1,
        atol=1e-12,
    )
    np.testing.assert_allclose(flockkit.rigid.quaternion_matrix(a.as_quat()), a.as_matrix(), atol=1e-12)
    u = rng.random((20, 1))
    halfway = flockkit.rigid.slerp(a.as_quat(), b.as_quat(), u)
    np.testing.assert_allclose(angle(halfway, a.as_quat()), u[:, 0] * angle(a.as_quat(), b.as_quat()), atol=1e-9)
