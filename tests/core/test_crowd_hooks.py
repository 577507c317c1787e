"""Part hooks (a cluster hung on a joint of another, paper 003 section 4.2) and procedural per-bone
overrides after blending (section 4.6; LookAt), checked against forward kinematics and
geometry written out here."""

import math

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Hook, LookAt, Pose, SkeletalClip, Skeleton, Stream, StreamPool
from flockkit.errors import ValidationError
from flockkit.testing import inputs

WALKER = inputs.walker()
HEAD = WALKER.skeleton.index("head")
HAND = WALKER.skeleton.index("hand.R")


def flag(seconds=1.0, fps=30.0):
    """A three-joint flag waving about its pole: its root keyed at the identity."""
    skeleton = Skeleton(names=["pole", "cloth", "tip"], parents=[-1, 0, 1],
                        rest=Pose(rotations=np.tile([0.0, 0, 0, 1], (3, 1)), translations=[[0, 0, 0], [0, 0, 0.4],
                                                                                             [0.3, 0, 0]]))  # fmt: skip
    phase = 2 * np.pi * np.arange(int(seconds * fps) + 1) / (seconds * fps)
    rotations = np.tile([0.0, 0, 0, 1], (len(phase), 3, 1))
    rotations[:, 1, 2], rotations[:, 1, 3] = np.sin(0.4 * np.sin(phase)), np.cos(0.4 * np.sin(phase))
    return SkeletalClip(skeleton=skeleton, fps=fps, rotations=rotations, translations=np.zeros((len(phase), 3)))


def play(clip, **params):
    return flockkit.get("controller", "clip", clip=clip, **params)


OFFSET = np.array([[0, -1, 0, 0.05], [1, 0, 0, 0], [0, 0, 1, -0.1], [0, 0, 0, 1.0]])


def hooked_crowd(n=8, **params):
    streams = [Stream(controller=play(WALKER), history=20), Stream(controller=play(WALKER, rate=1.6), history=24),
               Stream(controller=play(flag()), history=15), Stream(controller=play(flag(), rate=0.5), history=15,
                                                                   default="Stopped")]  # fmt: skip
    pool = StreamPool(streams, fps=30)
    return Crowd(pool, n_agents=n, clusters={"body": np.arange(n) % 2, "flag": 2}, seed=1,
                 hooks=[Hook(part="flag", parent="body", joint="hand.R", offset=OFFSET)], **params)  # fmt: skip


def test_a_hooked_part_stays_on_its_joint_through_transitions_and_dilation():
    crowd = hooked_crowd()
    for frame in range(90):
        if frame == 5:
            crowd.transition_to_streamed([0, 2, 4], "body", 1, blend_time=0.5)
        if frame == 20:  # the flag into a Stopped stream: dilating
            crowd.transition_to_streamed([1, 2, 3], "flag", 3, blend_time=0.3, time_to_dilate=1.0)
        crowd.update()
        body = crowd.poses(cluster="body", space="world").astype(np.float64)
        flags = crowd.poses(cluster="flag", space="world").astype(np.float64)
        # the flag's own forward kinematics, from its local pose, placed at the hand times the offset
        local = crowd.poses(cluster="flag")
        own = crowd.skeletons[1].world(Pose(rotations=local.rotations, translations=local.translations))
        expected = body[:, HAND] @ OFFSET
        np.testing.assert_allclose(flags[:, 0], expected @ own[:, 0], atol=2e-6)
        np.testing.assert_allclose(flags[:, 0], expected, atol=2e-6)  # the pole keys the identity
        np.testing.assert_allclose(flags, expected[:, None] @ own, atol=2e-6)
    assert np.isnan(crowd.dilation_targets("flag")).all() and crowd.synchrony("flag", [1, 2, 3]) < 1


def test_hooks_are_refused_where_they_cannot_hold():
    streams = [Stream(controller=play(WALKER), history=5), Stream(controller=play(flag()), history=5)]
    pool = StreamPool(streams, fps=30)
    clusters = {"body": [0, 0, -1], "flag": [1, 1, 1]}
    with pytest.raises(ValidationError, match="agent 2 has a 'flag' part hung on 'body' but no 'body' part"):
        Crowd(pool, n_agents=3, clusters=clusters, hooks=[Hook(part="flag", parent="body", joint="hand.R")])
    clusters = {"body": 0, "flag": 1, "flag2": 1}
    with pytest.raises(ValidationError, match="no joint 'hand'"):
        Crowd(pool, n_agents=3, clusters=clusters, hooks=[Hook(part="flag", parent="body", joint="hand")])
    with pytest.raises(ValidationError, match="cycle"):
        Crowd(
            pool,
            n_agents=3,
            clusters=clusters,
            hooks=[Hook(part="flag", parent="flag2", joint="tip"), Hook(part="flag2", parent="flag", joint="tip")],
        )
    with pytest.raises(ValidationError, match="4 x 4"):
        Hook(part="flag", parent="body", joint="hand.R", offset=np.eye(3))


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle_between(a, b):
    return np.arccos(np.clip(np.sum(unit(a) * unit(b), axis=-1), -1, 1))


FORWARD = np.array([0.0, 1.0, 0.0])  # the walker faces +y; its head's local +y


def looking_crowd(limit, placement=None):
    look = LookAt("head", n_agents=6, forward=FORWARD, max_angle=limit, blend_time=0.5)
    pool = StreamPool([Stream(controller=play(WALKER), history=20)], fps=30)
    crowd = Crowd(pool, n_agents=6, clusters={"body": 0}, seed=2, overrides={"body": [look]})
    if placement is not None:
        crowd.placement = placement
    return crowd, look


def plain_crowd():
    pool = StreamPool([Stream(controller=play(WALKER), history=20)], fps=30)
    return Crowd(pool, n_agents=6, clusters={"body": 0}, seed=2)


def test_look_at_points_the_head_at_its_target_within_the_limit_and_changes_nothing_else():
    rng = np.random.default_rng(0)
    placement = np.tile(np.eye(4), (6, 1, 1))
    placement[:, :3, :3] = 2.0 * np.stack([flockkit.rigid.rotation(a, [0, 0, 1]) for a in rng.uniform(-3, 3, 6)])
    placement[:, :3, 3] = rng.normal(size=(6, 3)) * 5  # agents scaled, turned and moved in the world
    limit = math.radians(50)
    crowd, look = looking_crowd(limit, placement)
    plain = plain_crowd()
    crowd.update(), plain.update()
    heads = (placement[:, None] @ plain.poses(space="world").astype(np.float64))[:, HEAD, :3, 3]
    # targets: three within the cone of the animated facing, three far outside it
    facing = unit((placement[:, :3, :3] @ plain.poses(space="world").astype(np.float64)[:, HEAD, :3, :3]) @ FORWARD)
    side = unit(np.cross(facing, [0.0, 0.0, 1.0]))
    turns = np.radians([10, 30, 45, 80, 120, 170])
    targets = heads + 3 * (np.cos(turns)[:, None] * facing + np.sin(turns)[:, None] * side)
    look.look(np.arange(6), targets, time=crowd.time)
    for _ in range(20):  # past the blend time: full weight
        crowd.update(), plain.update()
        np.testing.assert_allclose(look.weights(crowd.time), np.clip((crowd.time - 1 / 30) / 0.5, 0, 1) ** 2
                                   * (3 - 2 * np.clip((crowd.time - 1 / 30) / 0.5, 0, 1)))  # fmt: skip
    assert np.all(look.weights(crowd.time) == 1)
    before = plain.poses(space="world").astype(np.float64)
    after = crowd.poses(space="world").astype(np.float64)
    world_after, world_before = placement[:, None] @ after, placement[:, None] @ before
    animated = world_before[:, HEAD, :3, :3] @ FORWARD
    now = world_after[:, HEAD, :3, :3] @ FORWARD
    wanted = targets - world_after[:, HEAD, :3, 3]
    within = turns[:3]
    # inside the cone: the head's forward points at the target
    assert angle_between(now[:3], wanted[:3]).max() < 1e-5, angle_between(now, wanted)
    # outside: turned exactly the limit, towards the target (on the great circle)
    np.testing.assert_allclose(angle_between(animated[3:], now[3:]), limit, atol=1e-5)
    np.testing.assert_allclose(angle_between(now[3:], wanted[3:]) + limit, angle_between(animated[3:], wanted[3:]),
                               atol=1e-5)  # fmt: skip
    assert np.all(angle_between(animated, now) <= limit + 1e-6) and np.all(within < limit)
    # every other joint's local transform is untouched; the head's position too
    local, plain_local = crowd.poses(), plain.poses()
    others = np.arange(WALKER.skeleton.n_joints) != HEAD
    np.testing.assert_array_equal(local.rotations[:, others], plain_local.rotations[:, others])
    np.testing.assert_array_equal(local.translations, plain_local.translations)
    # releasing eases the head back to its animation
    look.release(np.arange(6), time=crowd.time)
    for _ in range(16):
        crowd.update(), plain.update()
    np.testing.assert_allclose(crowd.poses().rotations, plain.poses().rotations, atol=1e-7)


def test_overrides_are_declared_and_checked():
    pool = StreamPool([Stream(controller=play(WALKER), history=5)], fps=30)
    with pytest.raises(ValidationError, match="no joint 'neck'"):
        Crowd(pool, n_agents=2, clusters={"body": 0}, overrides={"body": [LookAt("neck", n_agents=2)]})
    with pytest.raises(ValidationError, match="made for 3 agents"):
        Crowd(pool, n_agents=2, clusters={"body": 0}, overrides={"body": [LookAt("head", n_agents=3)]})
    with pytest.raises(ValidationError, match="not a pose override"):
        Crowd(pool, n_agents=2, clusters={"body": 0}, overrides={"body": [object()]})
    with pytest.raises(ValidationError, match="max_angle"):
        LookAt("head", n_agents=2, max_angle=4.0)

    class Sneaky:
        """Declares the head but changes every joint: the crowd takes only the head."""

        joints = ("head",)

        def apply(self, pose, *, skeleton, agents, origins, time):
            return Pose(rotations=np.tile([0.0, 0, 1, 0], pose.rotations.shape[:-1] + (1,)),
                        translations=pose.translations + 1)  # fmt: skip

    crowd = Crowd(pool, n_agents=2, clusters={"body": 0}, seed=0, overrides={"body": [Sneaky()]})
    plain = Crowd(pool, n_agents=2, clusters={"body": 0}, seed=0)
    changed, kept = crowd.poses(), plain.poses()
    np.testing.assert_array_equal(changed.rotations[:, HEAD], np.tile([0.0, 0, 1, 0], (2, 1)))
    others = np.arange(WALKER.skeleton.n_joints) != HEAD
    np.testing.assert_array_equal(changed.rotations[:, others], kept.rotations[:, others])
    np.testing.assert_array_equal(changed.translations[:, others], kept.translations[:, others])
