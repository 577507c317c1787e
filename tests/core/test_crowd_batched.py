"""Streams advanced in one batched call per controller class (``Capabilities.batch``) write the
same poses as their controllers' own ``pose``, rounded to float32; live controllers
(``Capabilities.live``) show what is fed in the very next update."""

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool, UniquePool
from flockkit.errors import ValidationError
from flockkit.testing import inputs


def clip_player(clip, **params):
    return flockkit.get("controller", "clip", clip=clip, **params)


class OneByOne:
    """A clip player that does not declare batch: the pool calls its ``pose``, as a third-party
    controller's, through the prefetch path (the reference)."""

    def __init__(self, player):
        self.player = player
        self.skeleton = player.skeleton

    def pose(self, times):
        return self.player.pose(times)

    def events(self, start, stop):
        return self.player.events(start, stop)


def players(clips, rng):
    made = []
    for k, clip in enumerate(clips):
        made.append(clip_player(clip, rate=float(rng.uniform(0.3, 2.5)), start=float(rng.uniform(0, 3)),
                                loop=bool(k % 3)))  # fmt: skip
    return made


def check_equal_to_pose(controllers, frames=70, fps=30.0):
    """Run a pool of `controllers` (batched) and read every frame; each equals pose at its time."""
    pool = StreamPool([Stream(controller=c, history=3) for c in controllers], fps=fps)
    assert pool.batched.all()
    for frame in range(1, frames):
        pool.advance()
        for k, c in enumerate(controllers):
            expected = c.pose([frame / fps])
            got = pool.read(k, 0)
            np.testing.assert_array_equal(got.rotations, expected.rotations[0].astype(np.float32))
            np.testing.assert_array_equal(got.translations, expected.translations[0].astype(np.float32))
    return pool


def test_batched_streams_equal_their_controllers_pose():
    rng = np.random.default_rng(3)
    clips = [inputs.random_clip(7, frames=f, seed=f) for f in (1, 2, 5, 30, 91)]
    clips.append(inputs.walker())
    by_size = {}  # a batch is one joint count
    for clip in clips:
        by_size.setdefault(clip.skeleton.n_joints, []).append(clip)
    controllers = [c for group in by_size.values() for c in players(group, rng)]
    pool = check_equal_to_pose(controllers)
    assert len(pool._batches) == len(by_size)
    assert pool.memory_parts()["prefetch"] == 0  # nothing evaluated ahead


def test_batched_and_prefetched_pools_hold_the_same_store():
    rng = np.random.default_rng(5)
    clips = [inputs.random_clip(12, frames=40, seed=k) for k in range(6)]
    batched = players(clips, rng)
    one = StreamPool([Stream(controller=c, history=8) for c in batched], fps=24.0)
    two = StreamPool([Stream(controller=OneByOne(c), history=8) for c in batched], fps=24.0)
    assert one.batched.all() and not two.batched.any()
    for _ in range(50):
        one.advance()
        two.advance()
    np.testing.assert_array_equal(one.store, two.store)


def test_real_clips_batched(shared_data):
    """The shared BVH take (frames) and the Fox's glTF clips (channels: evaluated one by one
    inside the batch) give what their controllers give."""
    rng = np.random.default_rng(7)
    take = flockkit.io.read_clips(shared_data / "cmu-mocap-bvh" / "01_01.bvh")
    fox = flockkit.io.read_clips(shared_data / "fox-gltf" / "Fox.glb")
    for clips in (list(take.values()), list(fox.values())):
        check_equal_to_pose(players(clips, rng), frames=40)


def test_stopped_batched_streams_restart_from_zero():
    clip = inputs.random_clip(9, frames=20, seed=1)
    controllers = [clip_player(clip, rate=1.3), clip_player(clip, rate=0.7)]
    pool = StreamPool([Stream(controller=c, history=4, default="Stopped") for c in controllers])
    pool.acquire(np.array([1]))
    np.testing.assert_array_equal(pool.read(1, 0).rotations, controllers[1].pose([0.0]).rotations[0].astype(np.float32))
    assert not pool.is_running(0)


def locomotion():
    walker = inputs.walker()
    idle = flockkit.SkeletalClip(skeleton=walker.skeleton, fps=walker.fps, rotations=walker.rotations[:1],
                                 translations=walker.translations[:1], name="idle")  # fmt: skip
    return flockkit.get("controller", "locomotion", clips=(idle, walker), speeds=(0.0, 1.4))


@pytest.mark.parametrize("where", ["stream", "unique"])
def test_live_input_changes_the_pose_in_the_very_next_update(where):
    """Two crowds alike; one is fed a new speed (then a turn) before an update: its pose differs
    from the other's in that update, and not before."""
    crowds = []
    for _ in range(2):
        controller = locomotion()
        if where == "stream":
            pool = StreamPool([Stream(controller=controller, history=1)])
            crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, seed=1)
        else:
            pool = StreamPool([Stream(controller=locomotion(), history=1)])
            unique = UniquePool(1, max_bones=controller.skeleton.n_joints)
            unique.set(0, controller)
            crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, unique=unique, seed=1)
            crowd.transition_to_unique([0, 1, 2], "body", 0, blend_time=1e-6)
        crowds.append((crowd, controller))
    assert pool.live.all()
    for crowd, _ in crowds:
        for _ in range(4):
            crowd.update()
    same = [crowd.entries(None, "body") for crowd, _ in crowds]
    np.testing.assert_array_equal(same[0], same[1])
    for inputs_fed in ({"speed": 1.4}, {"turn": 1.0}):
        crowds[1][1].feed(**inputs_fed)
        for crowd, _ in crowds:
            crowd.update()
        a, b = (crowd.entries(None, "body") for crowd, _ in crowds)
        assert np.abs(a - b).max() > 1e-3, f"feeding {inputs_fed} did not show in the next update"
        crowds[0][1].feed(**inputs_fed)  # both fed alike again from here


def test_live_controller_refuses_bad_inputs():
    controller = locomotion()
    with pytest.raises(ValidationError, match="unknown input"):
        controller.feed(sped=1.0)
    with pytest.raises(ValidationError):
        controller.feed(speed=-1.0)
    with pytest.raises(ValidationError):
        controller.feed(turn=float("inf"))
