"""Clips sample as their files define them: every skeletal clip of ../shared/data and generated
glTF clips of each interpolation, keys at uneven times, against tests/core/animation_spec.py (an
evaluator written from the glTF 2.0 specification and the BVH definition that shares no code
with flockkit), at every key, between keys and past the ends, to 1e-5 of the skeleton's size;
and the crowd's streams read those poses."""

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Channel, SkeletalClip, Stream, StreamPool
from flockkit.errors import ValidationError
from flockkit.io import read_clips

from . import animation_spec as spec

BAR = 1e-5  # of the skeleton's size: the diagonal of its joints' bounding box at rest
ASSETS = ["fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb"]


def diagonal(points) -> float:
    points = np.asarray(points).reshape(-1, 3)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def times_to_check(keys, duration, seed=0):
    """Every key, the midpoint between consecutive keys, random times, and times past the ends."""
    keys = np.unique(keys)
    rng = np.random.default_rng(seed)
    return np.concatenate([keys, (keys[:-1] + keys[1:]) / 2, rng.uniform(0, duration, 60), [0.0, duration + 0.25]])


def sampling_errors(path):
    """Per clip of the glTF file `path`: (name, world-position error, local translation error,
    both over the skeleton's size, local rotation error in radians)."""
    gltf = spec.GltfAnimation(path)
    found = []
    for name, clip in read_clips(path).items():
        animation = gltf.names.index(name.rpartition("/")[2])
        nodes = [spec.node_of(gltf, n) for n in clip.skeleton.names]
        rest = gltf.world(None, [0.0])
        size = diagonal([rest[n][0, :3, 3] for n in nodes])
        times = times_to_check(gltf.key_times(animation), gltf.duration(animation))
        pose = clip.sample(times)
        world = gltf.world(animation, times)
        theirs = np.stack([world[n][:, :3, 3] for n in nodes], axis=1)
        position = np.linalg.norm(clip.skeleton.positions(pose) - theirs, axis=-1).max() / size
        translation, rotation, _ = gltf.local(animation, times)
        moved = np.linalg.norm(pose.translations - np.stack([translation[n] for n in nodes], axis=1), axis=-1)
        dot = np.abs(np.sum(pose.rotations * np.stack([rotation[n] for n in nodes], axis=1), axis=-1))
        turned = 2 * np.arccos(np.clip(dot, 0, 1))
        found.append((name, position, moved.max() / size, turned.max()))
    return found


@pytest.mark.parametrize("asset", ASSETS)
def test_every_clip_of_the_shared_gltf_files_samples_as_the_spec_says(shared_data, asset):
    errors = sampling_errors(shared_data / asset)
    assert len(errors) == {"fox-gltf/Fox.glb": 3, "robot-expressive-gltf/RobotExpressive.glb": 14}[asset]
    for name, position, translation, rotation in errors:
        assert position <= BAR and translation <= BAR and rotation <= BAR, name


def test_the_morph_stress_test_has_no_skeletal_clip(shared_data):
    path = shared_data / "morph-stress-test-gltf" / "MorphStressTest.gltf"
    assert not spec.GltfAnimation(path).json.get("skins")
    with pytest.raises(ValidationError, match="no skin"):
        read_clips(path)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_generated_clips_of_every_interpolation_sample_as_the_spec_says(tmp_path, seed):
    path = tmp_path / "generated.glb"
    spec.write_clips(path, spec.generated_clips(seed=seed))
    errors = sampling_errors(path)
    assert [e[0] for e in errors] == ["linear", "step", "cubicspline", "mixed"]
    for name, position, translation, rotation in errors:
        assert position <= BAR and translation <= BAR and rotation <= BAR, name


def test_a_glTF_clip_keeps_its_keys(tmp_path):
    path = tmp_path / "generated.glb"
    clips = spec.generated_clips(seed=3)
    spec.write_clips(path, clips)
    read = read_clips(path)
    for name, channels in clips.items():
        clip = read[name]
        keys = np.unique(np.concatenate([c["times"] for c in channels]).astype(np.float32))
        np.testing.assert_array_equal(clip.key_times, keys)
        assert clip.duration == keys[-1]
        assert sorted((c.joint, c.path, c.interpolation) for c in clip.channels) == sorted(
            (c["joint"] + 0, c["path"], c["interpolation"]) for c in channels
        )
        # frames: the clip sampled at its frame rate, to the end
        assert clip.n_frames == int(np.ceil(clip.duration * clip.fps - 1e-3)) + 1
        frames = clip.sample(np.arange(clip.n_frames) / clip.fps)
        np.testing.assert_allclose(clip.rotations, frames.rotations, atol=1e-15)


def write_bvh(path, frames, frame_time):
    """A two-joint BVH (hips with position and Z X Y rotation channels, a knee with X Z Y
    rotations, an end site) holding `frames` (F, 9)."""
    text = (
        "HIERARCHY\nROOT hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
        "Yrotation\n JOINT knee\n {\n  OFFSET 0 -3 1\n  CHANNELS 3 Xrotation Zrotation Yrotation\n"
        "  End Site\n  {\n   OFFSET 0 -2 0.5\n  }\n }\n}\n"
        f"MOTION\nFrames: {len(frames)}\nFrame Time: {frame_time}\n"
        + "\n".join(" ".join(f"{v:.6f}" for v in row) for row in frames)
        + "\n"
    )
    path.write_text(text)


def test_a_bvh_take_is_slerped_between_its_frames(tmp_path):
    rng = np.random.default_rng(0)
    frames = np.concatenate([rng.normal(size=(5, 3)), rng.uniform(-170, 170, (5, 6))], axis=1)
    path = tmp_path / "swing.bvh"
    write_bvh(path, frames, 0.25)  # turns of up to 170 degrees a frame: nlerp would stray by far
    clip = read_clips(path)["swing"]
    reference = spec.BvhMotion(path, rate=4.0)
    times = np.concatenate([np.arange(5) / 4.0, np.linspace(0, 1, 41) + 0.003, [1.5]])
    theirs = reference.positions(times)
    size = diagonal(reference.positions(np.arange(5) / 4.0))
    assert np.linalg.norm(clip.skeleton.positions(clip.sample(times)) - theirs, axis=-1).max() <= BAR * size


def test_the_cmu_take_samples_as_its_frames_define(shared_data):
    path = shared_data / "cmu-mocap-bvh" / "01_01.bvh"
    clip = read_clips(path)["01_01"]
    reference = spec.BvhMotion(path, rate=clip.fps)  # frame k at k / 120 (Frame Time 0.008333, rounded)
    keys = np.arange(clip.n_frames) / clip.fps
    times = np.concatenate([keys[::50], (keys[:-1:50] + keys[1::50]) / 2, [keys[-1] + 1.0]])
    size = diagonal(reference.positions(keys[::40]))
    error = np.linalg.norm(clip.skeleton.positions(clip.sample(times)) - reference.positions(times), axis=-1)
    assert error.max() <= BAR * size
    # frames at another rate keep the take's keys
    slow = read_clips(path, fps=30)["01_01"]
    assert slow.fps == 30.0 and slow.n_frames == int(np.ceil(clip.duration * 30 - 1e-3)) + 1
    np.testing.assert_allclose(slow.sample(times).rotations, clip.sample(times).rotations, atol=1e-12)


def test_a_stream_reads_the_clip_as_the_spec_samples_it(shared_data):
    path = shared_data / "fox-gltf" / "Fox.glb"
    run = read_clips(path)["Run"]  # keys jump from frame 16 to 20.8 at 24 fps
    gltf = spec.GltfAnimation(path)
    player = flockkit.get("controller", "clip", clip=run)
    pool = StreamPool([Stream(controller=player, history=45)], fps=30)
    while pool.filled[0] < 45:
        pool.advance()
    times = (pool.clock[0] - 1 - np.arange(45)) / 30.0  # offset k: the frame evaluated k frames before the last
    world = gltf.world(gltf.names.index("Run"), np.mod(times, run.duration))  # the player loops
    nodes = [spec.node_of(gltf, n) for n in run.skeleton.names]
    theirs = np.stack([world[n][:, :3, 3] for n in nodes], axis=1)
    ours = np.stack([run.skeleton.positions(pool.read(0, k)) for k in range(45)])  # float32 poses
    rest = gltf.world(None, [0.0])
    size = diagonal([rest[n][0, :3, 3] for n in nodes])
    assert np.linalg.norm(ours - theirs, axis=-1).max() <= BAR * size


def test_resampling_is_asked_for_and_lossy_between_keys(tmp_path):
    path = tmp_path / "generated.glb"
    spec.write_clips(path, spec.generated_clips(seed=0))
    step = read_clips(path)["step"]
    frames = step.resampled(30)
    assert frames.fps == 30.0 and not frames.channels and frames.duration >= step.duration
    grid = np.arange(frames.n_frames) / 30.0
    np.testing.assert_allclose(frames.sample(grid).translations, step.sample(grid).translations, atol=1e-12)
    between = grid[:-1] + 1 / 60
    assert np.abs(frames.sample(between).translations - step.sample(between).translations).max() > 0.1


def test_channels_are_checked():
    skeleton = flockkit.Skeleton(names=["a", "b"], parents=[-1, 0])
    turn = Channel(joint="b", path="rotation", times=[0.1, 0.5], values=[[0, 0, 0, 1.0], [0, 0, 1.0, 0]])
    clip = SkeletalClip(skeleton=skeleton, channels=[turn])
    assert clip.duration == 0.5 and clip.fps == 2.5 and clip.n_frames == 3
    np.testing.assert_allclose(clip.sample([0.0, 0.3]).rotations[:, 1], [[0, 0, 0, 1], [0, 0, 0.5**0.5, 0.5**0.5]])
    np.testing.assert_array_equal(clip.sample([0.3]).rotations[0, 0], [0, 0, 0, 1])  # unmoved: at rest
    with pytest.raises(ValidationError, match="frames .* or channels, not both"):
        SkeletalClip(skeleton=skeleton, channels=[turn], fps=10, rotations=np.tile([0, 0, 0, 1.0], (2, 2, 1)),
                     translations=np.zeros((2, 3)))  # fmt: skip
    with pytest.raises(ValidationError, match="which an earlier channel moves"):
        SkeletalClip(skeleton=skeleton, channels=[turn, turn])
    with pytest.raises(ValidationError, match="no joint 'c'"):
        SkeletalClip(
            skeleton=skeleton, channels=[Channel(joint="c", path="rotation", times=[0], values=[[0, 0, 0, 1]])]
        )
    with pytest.raises(ValidationError, match="increase strictly"):
        Channel(joint=0, path="translation", times=[0.2, 0.2], values=np.zeros((2, 3)))
    with pytest.raises(ValidationError, match="CUBICSPLINE"):
        Channel(joint=0, path="translation", times=[0, 1], values=np.zeros((2, 3)), interpolation="CUBICSPLINE")
    with pytest.raises(ValidationError, match="interpolation"):
        Channel(joint=0, path="translation", times=[0, 1], values=np.zeros((2, 3)), interpolation="SMOOTH")
    with pytest.raises(ValidationError, match=r"shape \(2, 3\)"):
        Channel(joint=0, path="translation", times=[0, 1], values=np.zeros((3, 3)))
    with pytest.raises(ValidationError, match="frames .* or channels"):
        SkeletalClip(skeleton=skeleton, fps=10)
