"""Root motion: extracted from clips that carry it, played by crowds whose agents advance by it
(through loops, offsets, playback rates, time dilation, blends and stream switches), and chosen
by a Driver instead of the trajectories. Expected values come from the clip's closed form
(``flockkit.testing.inputs.strider``), composed frame by frame as 4 x 4 matrices."""

import math

import numpy as np
import pytest

import flockkit
from flockkit.crowd import (
    Crowd,
    RootMotion,
    SkeletalClip,
    Stream,
    StreamPool,
    carries_root_motion,
    extract_root_motion,
)
from flockkit.crowd.drive import Driver, Gait, StateMachine
from flockkit.errors import ValidationError
from flockkit.skeleton import ground_matrices
from flockkit.testing import inputs

SPEED, TURN, SECONDS, FPS = 1.0, 0.3, 2.0, 30.0
# A root track is linear between its keys (the clip's frames) while the strider walks an arc:
# read between keys, the chord is off the arc by at most (speed / fps)^2 turn / (8 speed)... about
# 4e-5 units here; reads at whole frames are exact.
BETWEEN_KEYS = 1e-4


def arc(u, up="z"):
    """The strider's motion joint at clip time `u` (any number of loops on) as a 4 x 4 matrix in
    its model space, from its definition: each loop's end composed with the position within the
    loop, step by step."""
    axes = np.eye(3) if up == "z" else np.array([[-1.0, 0, 0], [0, 0, 1], [0, 1, 0]])

    def within(t):
        h = TURN * t
        m = np.eye(4)
        m[:3, :3] = axes @ flockkit.rigid.rotation(h, [0, 0, 1]) @ axes.T
        m[:3, 3] = axes @ np.array([SPEED / TURN * (math.cos(h) - 1), SPEED / TURN * math.sin(h), 0.0])
        return m

    loops, rest = divmod(u, SECONDS)
    m = np.eye(4)
    for _ in range(int(loops)):
        m = m @ within(SECONDS)
    return m @ within(rest)


def strider(**params):
    return extract_root_motion(inputs.strider(fps=FPS, seconds=SECONDS, speed=SPEED, turn=TURN, **params))


def play(clip, **params):
    return flockkit.get("controller", "clip", clip=clip, **params)


@pytest.mark.parametrize("up", ["z", "y"])
def test_extraction_recovers_the_known_motion_and_leaves_the_clip_in_place(up):
    original = inputs.strider(fps=FPS, seconds=SECONDS, speed=SPEED, turn=TURN, up=up)
    in_place = extract_root_motion(original)
    track = in_place.root_motion
    assert isinstance(track, RootMotion) and track.joint == "hips" and track.up_axis == up
    assert in_place.duration == original.duration and len(track.times) == original.n_frames
    for k, t in enumerate(track.times):
        np.testing.assert_allclose(ground_matrices(track.keys[k], up), arc(t, up), atol=1e-12)
    np.testing.assert_allclose(ground_matrices(track.loop, up), arc(SECONDS, up), atol=1e-12)
    skeleton = original.skeleton
    world, still = skeleton.world(original.sample(track.times)), skeleton.world(in_place.sample(track.times))
    # in place: the hips over the origin, facing as at the start, heights kept
    u = "xyz".index(up)
    ground = [a for a in range(3) if a != u]
    np.testing.assert_allclose(still[:, 0, ground, 3], 0.0, atol=1e-12)
    facing = still[:, 0, :3, :3]
    np.testing.assert_allclose(facing, np.broadcast_to(facing[0], facing.shape), atol=1e-12)
    np.testing.assert_allclose(still[:, :, u, 3], world[:, :, u, 3], atol=1e-12)
    # the track's ground transform times the in-place pose is the clip, every joint, every key
    np.testing.assert_allclose(ground_matrices(track.keys, up)[:, None] @ still, world, atol=1e-12)
    assert carries_root_motion(original) and not carries_root_motion(in_place)
    assert not carries_root_motion(inputs.walker())


def test_a_straight_walk_and_a_turn_on_the_spot_are_detected():
    straight = inputs.strider(speed=1.0, turn=0.0)
    track = extract_root_motion(straight).root_motion
    np.testing.assert_allclose(track.loop, [0, SECONDS, 0, 0], atol=1e-12)
    spin = inputs.strider(speed=0.0, turn=0.1)  # turns 0.2 rad a loop on the spot
    assert carries_root_motion(spin) and carries_root_motion(straight)
    np.testing.assert_allclose(extract_root_motion(spin).root_motion.loop, [0, 0, 0, 0.2], atol=1e-12)
    # a lean below the tolerance is not root motion
    assert not carries_root_motion(inputs.strider(speed=0.001, turn=0.0))


def test_bad_root_motion_is_refused_by_name():
    clip = strider()
    with pytest.raises(ValidationError, match="root_motion lasts"):
        SkeletalClip(skeleton=clip.skeleton, fps=FPS, rotations=clip.rotations[:10],
                     translations=clip.translations[:10], root_motion=clip.root_motion)  # fmt: skip
    with pytest.raises(ValidationError, match="up axis"):
        RootMotion(times=[0, 1], translations=[[0, 0, 0], [0, 0, 1.0]], headings=[0, 0], up_axis="z")
    with pytest.raises(ValidationError, match="no joint 'pelvis'"):
        extract_root_motion(clip, joint="pelvis")


def test_the_clip_player_plays_root_motion_through_loops_rates_and_starts():
    clip = strider()
    for rate, start, loop in ((1.0, 0.0, True), (0.7, 0.5, True), (1.3, 0.2, False)):
        player = play(clip, rate=rate, start=start, loop=loop)
        times = np.linspace(0, 9.5, 40)
        found = ground_matrices(player.root_motion(times), "z")
        for t, m in zip(times, found):
            u = start + rate * t if loop else min(start + rate * t, SECONDS)
            expected = np.linalg.inv(arc(start)) @ arc(u)
            np.testing.assert_allclose(m, expected, atol=BETWEEN_KEYS)
    np.testing.assert_array_equal(play(inputs.walker()).root_motion([0.0, 3.0]), np.zeros((2, 4)))


def crowd_of(n, *, seed=0):
    clip = strider()
    streams = [Stream(controller=play(clip), history=20), Stream(controller=play(clip, rate=0.7), history=25),
               Stream(controller=play(clip, rate=1.2), history=30, default="Stopped")]  # fmt: skip
    pool = StreamPool(streams, fps=FPS)
    return Crowd(pool, n_agents=n, clusters={"body": np.arange(n) % 2}, seed=seed, root_motion="body")


def stream_time(crowd, stream, offset):
    """The clip time the part reads: its stream's frame (clock - 1 - offset) at the stream's rate."""
    controller = crowd.pool.streams[stream].controller
    return controller.start + controller.rate * (crowd.pool.clock[stream] - 1 - offset) / FPS


def test_agents_advance_by_their_clips_root_motion_at_their_offsets():
    crowd = crowd_of(12)
    buffer = crowd.instance_buffer()
    first = [stream_time(crowd, buffer["stream"][a, 0], buffer["offset"][a, 0]) for a in range(12)]
    np.testing.assert_array_equal(crowd.roots(), np.tile(np.eye(4), (12, 1, 1)))
    for _ in range(100):  # 3.3 s: through a loop and more
        crowd.update()
    for a in range(12):
        now = stream_time(crowd, buffer["stream"][a, 0], buffer["offset"][a, 0])
        expected = np.linalg.inv(arc(first[a])) @ arc(now)
        np.testing.assert_allclose(crowd.roots()[a], expected, atol=1e-9 if a % 2 == 0 else BETWEEN_KEYS)
    # the two rates travel different distances; agents at different offsets are not in step
    travelled = np.linalg.norm(crowd.roots()[:, :2, 3], axis=1)
    assert travelled[0::2].min() > travelled[1::2].max()


def test_root_motion_follows_dilation_blends_and_switches_frame_by_frame():
    crowd = crowd_of(6, seed=3)
    expected = np.tile(np.eye(4), (6, 1, 1))
    buffer = crowd.instance_buffer()

    def reads():
        """Per agent: (source clip time, target clip time or None, alpha)."""
        found = []
        alphas = crowd.alphas("body")
        for a in range(6):
            source = stream_time(crowd, buffer["stream"][a, 0], buffer["offset"][a, 0])
            blending = buffer["blend_time"][a, 0] > 0
            target = stream_time(crowd, buffer["target"][a, 0], buffer["target_offset"][a, 0]) if blending else None
            found.append((source, target, alphas[a] if blending else 0.0))
        return found

    def step(before):
        crowd.update()
        after = reads()
        for a, ((s0, t0, _), (s1, t1, alpha)) in enumerate(zip(before, after)):
            if t0 is not None and t1 is None:  # landed in this update: the target, now the source, at alpha 1
                t1, s1, alpha = s1, s1, 1.0
            # what each stream's read moved, mixed by alpha as (x, y, heading) in the agent's frame
            moves = []
            for u0, u1 in ((s0, s1), (t0, t1)):
                if u0 is None or u1 is None:
                    moves.append(np.zeros(3))
                    continue
                m = np.linalg.inv(arc(u0)) @ arc(u1)
                moves.append(np.array([m[0, 3], m[1, 3], math.atan2(m[1, 0], m[0, 0])]))
            blending = t0 is not None and t1 is not None
            x, y, h = (1 - alpha) * moves[0] + alpha * moves[1] if blending else moves[0]
            move = np.eye(4)
            move[:3, :3] = flockkit.rigid.rotation(h, [0, 0, 1])
            move[:2, 3] = x, y
            expected[a] = expected[a] @ move
        return after

    now = reads()
    for frame in range(150):
        if frame == 10:  # into the Stopped stream with time dilation, blending
            crowd.transition_to_streamed([0, 1, 2], "body", 2, blend_time=0.5, time_to_dilate=1.0)
            now = reads()
        if frame == 60:  # a change of rate at the same clip, blending
            crowd.transition_to_streamed([3, 4], "body", 1, blend_time=0.4)
            now = reads()
        if frame == 100:  # a switch without a blend
            crowd.assign([5, 0], "body", 0)
            now = reads()
        now = step(now)
    assert np.isfinite(crowd.dilation_targets("body")).sum() == 0  # every dilation arrived
    np.testing.assert_allclose(crowd.roots(), expected, atol=BETWEEN_KEYS)
    assert np.linalg.norm(crowd.roots()[:, :2, 3], axis=1).min() > 2.0  # everyone walked


def test_streams_without_root_motion_and_agents_without_the_cluster_stay_put():
    clip = strider()
    streams = [Stream(controller=play(clip), history=10), Stream(controller=play(inputs.walker()), history=10)]
    pool = StreamPool(streams, fps=FPS)
    crowd = Crowd(pool, n_agents=3, clusters={"body": [0, 1, 0], "hat": [1, -1, 1]}, root_motion="hat", seed=0)
    for _ in range(20):
        crowd.update()
    # the hat cluster reads the walker (in place): nobody moves; agent 1 has no hat
    np.testing.assert_array_equal(crowd.roots(), np.tile(np.eye(4), (3, 1, 1)))
    with pytest.raises(ValidationError, match="unknown cluster 'legs'"):
        Crowd(pool, n_agents=3, clusters={"body": 0}, root_motion="legs")


def line(n, seconds, speed):
    t = np.arange(0, seconds + 1e-9, 0.1)[:, None]
    positions = np.stack([speed * t + np.arange(n)[None], np.zeros((len(t), n))], axis=2)
    return flockkit.Motion(positions=positions, dt=0.1)


def test_a_driver_takes_roots_from_the_clips_or_the_trajectories():
    machine = StateMachine([Gait(name="idle", streams=0, high=0.3), Gait(name="walk", streams=0, low=0.3)])
    motion = line(4, 6.0, 1.0)
    crowd = crowd_of(4)
    with pytest.raises(ValidationError, match="root_motion='body'"):
        Driver(Crowd(crowd.pool, n_agents=4, clusters={"body": 0}), motion, machine, up="z", forward="y", scale=1.0,
               root_motion="clip")  # fmt: skip
    with pytest.raises(ValidationError, match="'trajectory' or 'clip'"):
        Driver(crowd, motion, machine, up="z", forward="y", scale=1.0, root_motion="animation")
    driver = Driver(crowd, motion, machine, up="z", forward="y", scale=2.0, root_motion="clip")
    start = driver.roots.copy()
    np.testing.assert_allclose(start[:, :2, 3], motion.positions[0])  # starting where the trajectories start
    for _ in range(60):
        driver.step()
    # each root is its start times the crowd's accumulated root motion (character units, scaled)
    np.testing.assert_allclose(driver.roots, start @ crowd.roots(), atol=1e-12)
    np.testing.assert_allclose(crowd.placement, driver.roots)
    # the arcs turn the agents left of their trajectories' heading by the clips' turn
    np.testing.assert_allclose(driver.heading, np.arctan2(crowd.roots()[:, 1, 0], crowd.roots()[:, 0, 0]), atol=1e-9)
    forward = driver.roots[:, :3, :3] @ np.array([0.0, 1.0, 0.0]) / 2.0
    np.testing.assert_allclose(forward[:, :2], np.stack([np.cos(driver.heading), np.sin(driver.heading)], 1), atol=1e-9)
    # a trajectory driver on the same motion stays on the path
    crowd = crowd_of(4)
    driver = Driver(crowd, motion, machine, up="z", forward="y", scale=2.0)
    for _ in range(60):
        driver.step()
    np.testing.assert_allclose(driver.roots[:, :2, 3], motion.positions[20], atol=1e-9)


def test_which_shared_clips_carry_root_motion(shared_data):
    """Fox Walk, Run and Survey loop in place (their hips sway within a loop and come back);
    RobotExpressive's Sitting, Standing and Death move its body across the ground (a sit back of
    23% of its height, a fall); the CMU BVH take walks 56 units (of the inch-like unit)."""
    found = {}
    for path, params in (("fox-gltf/Fox.glb", {}), ("robot-expressive-gltf/RobotExpressive.glb", {}),
                         ("cmu-mocap-bvh/01_01.bvh", {"meters_per_unit": "in"})):  # fmt: skip
        for name, clip in flockkit.io.read_clips(shared_data / path, **params).items():
            found[name] = carries_root_motion(clip)
            in_place = extract_root_motion(clip)
            track = in_place.root_motion
            skeleton = clip.skeleton
            below = skeleton.descendants(track.joint)
            world = skeleton.world(clip.sample(track.times))[:, below]
            still = skeleton.world(in_place.sample(track.times))[:, below]
            size = np.ptp(world[..., :3, 3].reshape(-1, 3), axis=0).max()
            rebuilt = ground_matrices(track.keys, skeleton.up_axis)[:, None] @ still
            assert np.abs(rebuilt - world)[..., :3, 3].max() < 1e-9 * size, name
            assert not carries_root_motion(in_place), name
    moving = {name for name, carries in found.items() if carries}
    assert moving == {"Sitting", "Standing", "Death", "01_01"}, moving
    assert {"Walk", "Run", "Survey", "Walking", "Running"} <= set(found)
