"""Crowds driven by trajectories (issue 17, part 1): roots on the paths, facing, speed states."""

import json
import math
import os
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool
from flockkit.crowd.drive import Driver, Gait, StateMachine, character_frame
from flockkit.errors import ValidationError
from flockkit.testing import inputs

WALKER = inputs.walker()


def machine(**params):
    return StateMachine(
        [Gait(name="idle", streams=0, high=0.3), Gait(name="walk", streams=[1, 2], speeds=[0.8, 1.4], low=0.3)],
        **params,
    )


def crowd_of(n):
    play = lambda **k: flockkit.get("controller", "clip", clip=WALKER, **k)  # noqa: E731
    pool = StreamPool([Stream(controller=play(rate=0.2), history=20), Stream(controller=play(), history=20),
                       Stream(controller=play(rate=1.7), history=20)], fps=30)  # fmt: skip
    return Crowd(pool, n_agents=n, clusters={"body": 0}, seed=0)


def test_the_state_machine_tiles_speeds_and_holds_near_thresholds():
    m = machine(hysteresis=0.05)
    np.testing.assert_array_equal(m.choose(np.array([0.0, 0.29, 0.3, 5.0])), [0, 0, 1, 1])
    # near the threshold an agent keeps its state until it is 0.05 past it
    np.testing.assert_array_equal(m.choose(np.array([0.33, 0.33, 0.27, 0.24]), np.array([0, 0, 1, 1])), [0, 0, 1, 0])
    for states, message in [
        ([Gait(name="a", streams=0, low=0.1)], "below 0.1"),
        ([Gait(name="a", streams=0, high=1.0), Gait(name="b", streams=1, low=0.5)], "overlap"),
        ([Gait(name="a", streams=0, high=1.0), Gait(name="b", streams=1, low=2.0)], "1.0..2.0"),
        ([Gait(name="a", streams=0, high=1.0)], "above 1.0"),
        ([Gait(name="a", streams=0, high=1.0), Gait(name="a", streams=1, low=1.0)], "repeat"),
    ]:
        with pytest.raises(ValidationError, match=message):
            StateMachine(states)
    with pytest.raises(ValidationError, match="2 speeds for 1 streams"):
        Gait(name="walk", streams=1, speeds=[1.0, 2.0])


def test_roots_follow_the_trajectories_and_face_their_velocity():
    t = np.arange(0, 6, 0.1)[:, None]
    speeds = np.array([[0.1, 1.0, 1.5]])  # idle, slow walk, fast walk
    turn = 0.3  # radians per second: arcs of circles at constant speeds
    positions = np.stack([speeds / turn * np.sin(turn * t), speeds / turn * (1 - np.cos(turn * t))], axis=2)
    motion = flockkit.Motion(positions=positions, dt=0.1)
    crowd = crowd_of(3)
    driver = Driver(crowd, motion, machine(), up="z", forward="y", turn_time=0.1)
    switches = []

    def heading_to():
        buffer = crowd.instance_buffer()
        return np.where(buffer["blend_time"][:, 0] > 0, buffer["target"][:, 0], buffer["stream"][:, 0])

    for _ in range(90):
        before = heading_to()
        driver.step()
        buffer = crowd.instance_buffer()
        changed = heading_to() != before
        switches.append(changed.any())
        # no stream switch without a blend: a part reading a new stream got there by blending
        assert np.all(buffer["blend_time"][changed, 0] > 0) or not changed.any()
        expected = np.array(
            [np.interp(crowd.time, np.arange(len(t)) * 0.1, positions[:, k, d]) for k in range(3) for d in range(2)]
        )
        np.testing.assert_allclose(driver.roots[:, :2, 3].ravel(), expected, atol=1e-12)  # exactly on the path
    # facing: the character's forward (+y) points along the velocity, within 5 degrees after turn_time
    velocity = np.gradient(positions, 0.1, axis=0)[int(round(crowd.time / 0.1))]
    forward = driver.roots[:, :3, :3] @ np.array([0.0, 1.0, 0.0])
    cosine = np.sum(forward[:, :2] * velocity, axis=1) / np.linalg.norm(velocity, axis=1)
    assert np.all(cosine > math.cos(math.radians(5)))
    np.testing.assert_allclose(
        driver.roots[:, :3, :3] @ [0, 0, 1.0], np.tile([0, 0, 1.0], (3, 1)), atol=1e-12
    )  # upright
    assert driver.state.tolist() == [0, 1, 1] and driver.stream.tolist() == [0, 1, 2]  # idle, nearest walking speeds
    assert not any(switches[1:])  # steady speeds: no flicker


def test_driving_refuses_what_does_not_fit():
    crowd = crowd_of(4)
    short = flockkit.Motion(positions=np.zeros((5, 3, 2)), dt=0.1)
    with pytest.raises(ValidationError, match="the trajectories have 3 agents; the crowd has 4"):
        Driver(crowd, short, machine())
    motion = flockkit.Motion(positions=np.zeros((5, 4, 2)), dt=0.1)
    with pytest.raises(ValidationError, match="state 'walk' names stream 7"):
        Driver(crowd, motion, StateMachine([Gait(name="idle", streams=0, high=1), Gait(name="walk", streams=7, low=1)]))
    with pytest.raises(ValidationError, match="different axes"):
        character_frame("y", "y")


def test_a_cheer_cue_starts_a_stopped_stream_spreads_the_cheering_and_ends():
    from flockkit.crowd.drive import Cue

    n = 200
    play = lambda **k: flockkit.get("controller", "clip", clip=WALKER, **k)  # noqa: E731
    pool = StreamPool([Stream(controller=play(rate=0.2), history=20), Stream(controller=play(), history=20),
                       Stream(controller=play(rate=1.7), history=20),
                       Stream(controller=play(rate=2.5), history=90, default="Stopped")], fps=30)  # fmt: skip
    crowd = Crowd(pool, n_agents=n, clusters={"body": 0}, seed=0)
    rng = np.random.default_rng(1)
    start = rng.uniform(-20, 20, (n, 2))
    heading = rng.uniform(0, 2 * np.pi, n)
    t = np.arange(0, 8, 0.1)[:, None, None]
    motion = flockkit.Motion(positions=start + t * np.stack([np.cos(heading), np.sin(heading)], axis=1), dt=0.1)
    home = np.arange(0, n, 2)
    cheer = Cue(time=1.0, agents=home, stream=3, duration=4.0, time_to_dilate=2.0, name="goal")
    driver = Driver(crowd, motion, machine(), up="z", forward="y", cues=[cheer])
    synchrony = {}
    for _ in range(int(6.5 * 30)):
        driver.step()
        synchrony[round(crowd.time, 2)] = crowd.synchrony("body", home)
    assert synchrony[1.0] == 1.0  # all cheer from the stream's head
    assert synchrony[3.0] < 0.05  # within the dilation time, under 5% of pairs move alike
    assert not pool.is_running(3) and np.all(driver.stream[home] != 3)  # the cheer ended: back to walking
    with pytest.raises(ValidationError, match="past the trajectories' end"):
        Driver(crowd_of(n), motion, machine(), cues=[Cue(time=9.0, agents=home, stream=3)])
    with pytest.raises(ValidationError, match="unknown stream id 9"):
        Driver(crowd_of(n), motion, machine(), cues=[Cue(time=1.0, agents=home, stream=9)])


def test_a_recorded_driven_crowd_exports_to_usd_skeletons_that_usd_reads_back(tmp_path):
    pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'flockkit[usd]')")
    from pxr import Usd, UsdGeom, UsdSkel

    from flockkit.crowd.record import record

    t = np.arange(0, 3, 0.1)[:, None, None]
    positions = np.array([[0.0, 0.0], [2.0, 1.0], [-1.0, 3.0]]) + t * np.array([[1.0, 0.2], [0.4, -1.0], [0.0, 1.3]])
    crowd = crowd_of(3)
    driver = Driver(crowd, flockkit.Motion(positions=positions, dt=0.1), machine(), up="z", forward="y")
    recording = record(driver, 1.0)
    assert recording.n_frames == 30 and recording.n_agents == 3
    # the last recorded frame is the crowd's current one
    np.testing.assert_allclose(recording.world()[-1], driver.world(), atol=1e-5)
    path = tmp_path / "crowd.usdc"
    recording.export_usd(path)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and stage.GetFramesPerSecond() == 30
    cache = UsdSkel.Cache()
    world = recording.world()
    for agent in range(3):
        root = stage.GetPrimAtPath(f"/Crowd/Agent_{agent}")
        query = cache.GetSkelQuery(UsdSkel.Skeleton(root.GetChild("Skeleton")))
        for frame in (0, 13, 29):
            skel = np.array(query.ComputeJointSkelTransforms(frame)).transpose(0, 2, 1)
            placed = np.array(UsdGeom.Xformable(root).ComputeLocalToWorldTransform(frame)).T
            np.testing.assert_allclose(placed @ skel, world[frame, agent], atol=1e-5)  # float32 precision
    with pytest.raises(ValidationError, match="seconds"):
        record(driver, 0)


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_CROWD = """
import json, sys
import bpy
path, frames = sys.argv[1], [int(f) for f in sys.argv[2:]]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=path)
scene = bpy.context.scene
armatures = sorted([o for o in scene.objects if o.type == "ARMATURE"], key=lambda o: o.name)
found = {}
for frame in frames:
    scene.frame_set(frame)
    found[frame] = [[list(a.matrix_world @ bone.head) for bone in a.pose.bones] for a in armatures]
print("RESULT" + json.dumps({"fps": scene.render.fps / scene.render.fps_base, "armatures": len(armatures),
                             "frames": found}))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_imports_a_driven_crowd_as_armatures_with_every_joint_in_place(tmp_path):
    from flockkit.crowd.record import record

    t = np.arange(0, 3, 0.1)[:, None, None]
    positions = np.array([[0.0, 0.0], [2.0, 1.0], [-1.0, 3.0]]) + t * np.array([[1.0, 0.2], [0.4, -1.0], [0.0, 1.3]])
    play = lambda **k: flockkit.get("controller", "clip", clip=WALKER, **k)  # noqa: E731
    pool = StreamPool([Stream(controller=play(rate=0.2), history=20), Stream(controller=play(), history=20),
                       Stream(controller=play(rate=1.7), history=20)], fps=24)  # fmt: skip
    crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, seed=0)
    driver = Driver(crowd, flockkit.Motion(positions=positions, dt=0.1), machine(), up="z", forward="y")
    recording = record(driver, 1.0)
    recording.export_usd(tmp_path / "crowd.usdc")
    frames = [0, 12, 23]
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_CROWD, str(tmp_path / "crowd.usdc"), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert found["fps"] == 24 and found["armatures"] == 3
    joints = recording.world()[..., :3, 3]
    for frame in frames:
        np.testing.assert_allclose(found["frames"][str(frame)], joints[frame], atol=1e-5)


def test_engine_buffers_replayed_by_a_small_shader_give_the_crowds_poses(tmp_path):
    """Replaying the .npz as a shader would (copy each frame's new heads into the store, find each
    part's rows from the heads and offsets, mix source and target by α) gives Crowd.entries."""
    from flockkit.crowd.record import write_engine_buffers

    def make():
        play = lambda **k: flockkit.get("controller", "clip", clip=WALKER, **k)  # noqa: E731
        pool = StreamPool([Stream(controller=play(), history=12), Stream(controller=play(rate=1.6), history=20),
                           Stream(controller=play(rate=0.5), history=16, default="Stopped")], fps=30)  # fmt: skip
        return Crowd(pool, n_agents=8, clusters={"body": np.arange(8) % 2}, seed=3)

    def script(crowd, frame):
        if frame == 3:
            crowd.transition_to_streamed([0, 1, 2, 3], "body", 2, blend_time=0.2, time_to_dilate=0.5)

    write_engine_buffers(make(), tmp_path / "buffers.npz", 1.0, on_frame=script)
    twin, expected = make(), []
    for frame in range(30):
        script(twin, frame)
        twin.update()
        expected.append(twin.entries(cluster="body"))
    with np.load(tmp_path / "buffers.npz", allow_pickle=False) as data:
        files = {name: data[name] for name in data.files}
    store = files["store"].copy()
    joints = WALKER.skeleton.n_joints

    def slot(frame, stream, behind):
        rows = files["lookup"][stream, (files["heads"][frame, stream] - behind) % files["history"][stream]]
        return np.stack([store[r : r + joints * 12].reshape(joints, 12) for r in rows])

    def read(frame, kind, stream, offset):
        """An offset between two frames (dilating) reads that far between them, slerped."""
        assert np.all(kind == 1)
        whole = np.floor(offset).astype(int)
        newer, older = slot(frame, stream, whole), slot(frame, stream, whole + 1)
        u = (offset - whole)[:, None, None]
        rotations = flockkit.rigid.slerp(newer[..., :4].astype(float), older[..., :4].astype(float), u)
        mixed = np.concatenate([rotations, newer[..., 4:] + u * (older[..., 4:] - newer[..., 4:])], axis=-1)
        return np.where(u > 0, mixed, newer).astype(np.float32)

    for frame in range(30):
        for s in np.flatnonzero(files["started"][frame] >= 0):  # a stream that started before its update
            before = (files["heads"][frame, s] - 1) % files["history"][s]
            start, row = files["started"][frame, s], files["lookup"][s, before]
            store[row : row + joints * 12] = files["entries"][start : start + joints * 12]
        for s in np.flatnonzero(files["written"][frame] >= 0):
            start, row = files["written"][frame, s], files["lookup"][s, files["heads"][frame, s]]
            store[row : row + joints * 12] = files["entries"][start : start + joints * 12]
        field = {name: files[f"instance_{name}"][frame, :, 0] for name in flockkit.crowd.INSTANCE.names}
        source = read(frame, field["kind"], field["stream"], field["offset"])
        blending = field["blend_time"] > 0
        if blending.any():
            target = read(frame, field["target_kind"][blending], field["target"][blending],
                          field["target_offset"][blending])  # fmt: skip
            alpha = np.clip(
                (files["time"][frame] - field["blend_start"][blending]) / field["blend_time"][blending], 0, 1
            )
            a, b = source[blending], target
            b = np.where(
                (np.sum(a[..., :4] * b[..., :4], axis=-1) < 0)[..., None],
                np.concatenate([-b[..., :4], b[..., 4:]], -1),
                b,
            )
            mixed = a + alpha[:, None, None] * (b - a)
            mixed[..., :4] /= np.linalg.norm(mixed[..., :4], axis=-1, keepdims=True)
            source[blending] = np.where((alpha == 1)[:, None, None], target, mixed)
        np.testing.assert_allclose(source, expected[frame], atol=1e-6)
    assert np.any(files["instance_blend_time"] > 0)  # the replay went through blends


def test_a_sky_of_flocks_flaps_on_the_climbs_and_glides_on_the_descents():
    """Many flocks in one call (synthesize_many from one graph), each bird an agent whose body
    plays one of two shared streams, flapping or gliding, chosen by its vertical speed: two
    streams serve every bird, at the birds' own offsets."""
    graph = inputs.graph(dims=3)
    walks = [flockkit.walk(graph, duration=6.0, seed=k) for k in range(20)]
    sky = flockkit.synthesize_many(graph, walks)  # 20 flocks of 6 birds
    pool = StreamPool(
        [
            Stream(controller=flockkit.get("controller", "clip", clip=inputs.bird(flapping=True)), history=15),
            Stream(controller=flockkit.get("controller", "clip", clip=inputs.bird(flapping=False)), history=15),
        ],
        fps=10,
    )
    crowd = Crowd(pool, n_agents=sky.n_agents, clusters={"body": 0}, seed=2)
    wings = StateMachine(
        [Gait(name="glide", streams=1, low=-math.inf, high=0.02), Gait(name="flap", streams=0, low=0.02)],
        on="climb",
        hysteresis=0.01,
    )
    driver = Driver(crowd, sky, wings, up="z", forward="y")
    for _ in range(40):
        driver.step()
        climb = driver._sample(driver._velocities, crowd.time)[:, 2]
        clear = np.abs(climb - 0.02) > 0.01  # beyond the hysteresis band, the state follows the climb
        assert np.all((driver.stream == 0)[clear] == (climb > 0.02)[clear])
    assert len(pool.streams) == 2 and {0, 1} <= set(driver.stream.tolist())
    assert crowd.synchrony("body") < 0.2  # birds on one stream differ by their offsets
    with pytest.raises(ValidationError, match="on must be 'speed' or 'climb'"):
        StateMachine([Gait(name="all", streams=0)], on="height")
