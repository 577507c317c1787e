"""Feet that stay put (issue 17, part 1): planting a clip's feet, switching rates in step, and the
Fox's foot sliding with speed-matched playback against fixed-rate."""

import numpy as np
import pytest

import flockkit
from flockkit.cli.demo import FOX, FOX_FEET, FOX_LEGS
from flockkit.crowd import Crowd, Stream, StreamPool, driven_sliding, ground_speed, plant_feet
from flockkit.errors import ValidationError
from flockkit.testing import inputs

LEGS = [("thigh.L", "shin.L", "foot.L"), ("thigh.R", "shin.R", "foot.R")]


def biped(fps=30.0, frames=40):
    """A pelvis on two legs (thigh, shin, foot; z up, facing y) that swing against each other with
    bent knees, the feet scuffing forward and back: a walk whose feet slide at any speed."""
    names = ["pelvis", "thigh.L", "shin.L", "foot.L", "thigh.R", "shin.R", "foot.R"]
    offsets = [[0, 0, 0.9], [-0.1, 0, 0], [0, 0, -0.5], [0, 0, -0.5], [0.1, 0, 0], [0, 0, -0.5], [0, 0, -0.5]]
    rest = flockkit.Pose(rotations=np.tile([0.0, 0, 0, 1], (7, 1)), translations=offsets)
    skeleton = flockkit.Skeleton(names=names, parents=[-1, 0, 1, 2, 0, 4, 5], rest=rest)
    phase = 2 * np.pi * np.arange(frames + 1) / frames
    rotations = np.tile([0.0, 0, 0, 1], (frames + 1, 7, 1))
    for thigh, shift in ((1, 0.0), (4, np.pi)):
        swing = -0.35 * np.sin(phase + shift) + 0.05 * np.sin(3 * (phase + shift))  # about x: + is forward
        knee = -0.35 - 0.25 * (1 - np.cos(phase + shift))  # always bent back
        for joint, angle in ((thigh, swing), (thigh + 1, knee)):
            rotations[:, joint] = np.stack([np.sin(angle / 2), 0 * angle, 0 * angle, np.cos(angle / 2)], axis=1)
    hips = np.tile(offsets[0], (frames + 1, 1))
    return flockkit.SkeletalClip(skeleton=skeleton, fps=fps, rotations=rotations, translations=hips, name="biped")


def positions(clip):
    return clip.skeleton.positions(flockkit.Pose(rotations=clip.rotations, translations=clip.translations))


def contact_runs(height, share):
    """Frames (of one loop) where a foot is within `share` of its height range above its lowest,
    as runs wrapping around the loop: computed here independently of plant_feet."""
    low = height - height.min() <= share * np.ptp(height)
    n = len(low)
    first = int(np.argmin(low))  # a lifted frame
    runs, run = [], []
    for k in list(range(first, n)) + list(range(first)):
        if low[k]:
            run.append(k)
        elif run:
            runs, run = runs + [run], []
    return runs + ([run] if run else [])


def test_planted_feet_move_back_in_a_line_at_one_speed_while_down_and_the_rest_is_untouched():
    raw = biped()
    speed, ease = 0.45, 2
    planted = plant_feet(raw, LEGS, up="z", forward="y", speed=speed, contact=0.25, ease=ease)
    before, after = positions(raw), positions(planted)
    period = raw.n_frames - 1
    touched = np.zeros(period, dtype=bool)
    for _, _, foot in LEGS:
        j = raw.skeleton.index(foot)
        runs = contact_runs(before[:period, j, 2], 0.25)
        assert len(runs) == 1 and len(runs[0]) >= 8
        run = runs[0]
        # the raw foot slides: its backward speed while down varies
        raw_steps = -np.diff(before[run, j, 1]) * raw.fps
        assert np.ptp(raw_steps) > 0.2
        down = after[run, j]
        np.testing.assert_allclose(-np.diff(down[:, 1]) * raw.fps, speed, atol=1e-6)
        np.testing.assert_allclose(down[:, 2], before[:period, j, 2].min(), atol=1e-6)
        np.testing.assert_allclose(down[:, 0], before[run, j, 0].mean(), atol=1e-6)
        for k in run:
            touched[[(k + d) % period for d in range(-ease, ease + 1)]] = True
    # only the legs' upper and middle joints turn, and only on and near contacts
    legs = [raw.skeleton.index(n) for leg in LEGS for n in leg[:2]]
    others = np.setdiff1d(np.arange(raw.skeleton.n_joints), legs)
    np.testing.assert_array_equal(planted.rotations[:, others], raw.rotations[:, others])
    np.testing.assert_array_equal(planted.rotations[:period][~touched], raw.rotations[:period][~touched])
    np.testing.assert_array_equal(planted.rotations[-1], planted.rotations[0])  # still a loop
    # bone lengths are the skeleton's: forward kinematics of rotations only
    np.testing.assert_allclose(np.linalg.norm(after[:, 3] - after[:, 2], axis=1), 0.5, atol=1e-9)


def test_planting_at_the_clips_own_speed_and_what_it_refuses():
    raw = biped()
    planted = plant_feet(raw, LEGS, up="z", forward="y")
    # the default speed is the clip's: what its feet travel back while down over the time they are down
    before = positions(raw)
    travel = duration = 0.0
    for _, _, foot in LEGS:
        j = raw.skeleton.index(foot)
        for run in contact_runs(before[:-1, j, 2], 0.25):
            travel += before[run[0], j, 1] - before[run[-1], j, 1]
            duration += (len(run) - 1) / raw.fps
    assert ground_speed(planted, [leg[2] for leg in LEGS], up="z", forward="y") == pytest.approx(travel / duration)
    for kwargs, message in [
        ({"legs": [("shin.L", "thigh.L", "foot.L")]}, "must be below"),
        ({"legs": [("thigh.L", "shin.L", "shin.L")]}, "must be below"),
        ({"legs": [("thigh.L", "shin.L")]}, r"legs\[0\] must be \(upper, middle, foot\)"),
        ({"legs": [("thigh.L", "shin.L", "toe.L")]}, "toe.L"),
        ({"legs": []}, "at least one leg"),
        ({"legs": LEGS, "contact": 1.0}, "contact"),
        ({"legs": LEGS, "speed": -1.0}, "speed"),
        ({"legs": LEGS, "forward": "q"}, "forward"),
    ]:
        kwargs.setdefault("up", "z")
        kwargs.setdefault("forward", "y")
        with pytest.raises(ValidationError, match=message):
            plant_feet(raw, **kwargs)
    # a clip whose feet come forward while down (played backwards) has no speed to plant at
    backwards = flockkit.SkeletalClip(skeleton=raw.skeleton, fps=raw.fps, rotations=raw.rotations[::-1],
                                      translations=raw.translations[::-1], name="moonwalk")  # fmt: skip
    with pytest.raises(ValidationError, match="'moonwalk' does not move its feet back along 'y'"):
        plant_feet(backwards, LEGS, up="z", forward="y")


def test_a_switch_of_rate_enters_the_new_stream_at_the_agents_own_pose_and_direction():
    walker = inputs.walker(seconds=2.0)
    play = flockkit.get("controller", "clip", clip=walker)
    pool = StreamPool([Stream(controller=play, history=40), Stream(controller=play, history=40)], fps=30)
    crowd = Crowd(pool, n_agents=4, clusters={"body": 0}, seed=3)
    crowd.assign(np.arange(4), "body", 0)
    for _ in range(70):
        crowd.update()
    # offsets 2 and 14 hold one pose, either side of a leg's turn, with the legs moving opposite ways
    offsets = np.array([2, 14, 25, 33])
    crowd.transition_to_streamed(np.arange(4), "body", 0, 0.1, offsets=offsets)
    for _ in range(4):
        crowd.update()  # the blends land; the offsets stay
    frames = pool.gather(np.array([0, 0]), np.array([2, 14]), walker.skeleton.n_joints)
    np.testing.assert_array_equal(frames[0], frames[1])
    # two streams of one clip started together: each agent's motion is at its own offset in the other
    np.testing.assert_array_equal(crowd.matching_offsets(np.arange(4), "body", 1), offsets)
    stopped = StreamPool(
        [Stream(controller=play, history=30), Stream(controller=play, history=30, default="Stopped")], fps=30
    )
    crowd = Crowd(stopped, n_agents=2, clusters={"body": 0}, seed=3)
    with pytest.raises(ValidationError, match="stream 1 is Stopped"):
        crowd.matching_offsets([0, 1], "body", 1)


def test_foxes_on_a_boids_flock_slide_three_times_less_with_speed_matched_playback(shared_data):
    fps = 24.0
    clips = flockkit.io.read_clips(shared_data / FOX)
    clips["Walk"] = plant_feet(clips["Walk"], FOX_LEGS)
    flock = flockkit.simulate(n_agents=24, steps=int(6 * fps), dt=1 / fps, seed=1)  # about 1 m/s
    rates = list(np.geomspace(0.5, 3.0, 24))
    # the model's joints span 116 units from nose to tail tip: a fox 0.78 m long, and 1.16 m (a red
    # fox's size, whose natural walk is nearly the flock's speed, so that fixed-rate nearly fits)
    for scale in (0.0067, 0.01):
        matched = driven_sliding(flock, clips["Walk"], clips["Survey"], FOX_FEET, rates, scale=scale)
        assert matched * 3 <= driven_sliding(flock, clips["Walk"], clips["Survey"], FOX_FEET, [1.0], scale=scale)
    # the clip as the file has it slides at any rate: planting is what makes matching pay
    raw = flockkit.io.read_clips(shared_data / FOX)
    assert driven_sliding(flock, raw["Walk"], raw["Survey"], FOX_FEET, rates, scale=0.01) > 3 * matched
