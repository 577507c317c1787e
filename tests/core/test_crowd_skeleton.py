"""Skeletons, clips and forward kinematics (paper 003), checked against evaluations that share
no code with flockkit: pygltflib and scipy for the glTF Fox, a small parser and scipy for the BVH."""

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

import flockkit
from flockkit.crowd import Event, Pose, SkeletalClip, Skeleton
from flockkit.errors import FileFormatError, ValidationError
from flockkit.io import read_clips


def chain(n=3):
    rest = Pose(rotations=np.tile([0.0, 0, 0, 1], (n, 1)), translations=[[0, 0, 0]] + [[1.0, 0, 0]] * (n - 1))
    return Skeleton(names=[f"j{k}" for k in range(n)], parents=[-1] + list(range(n - 1)), rest=rest)


def test_forward_kinematics_of_a_chain_by_hand():
    skeleton = chain(3)
    quarter = Rotation.from_euler("z", 90, degrees=True).as_quat()  # x, y, z, w
    pose = Pose(rotations=[quarter, quarter, [0, 0, 0, 1]], translations=[[0, 0, 0], [1, 0, 0], [1, 0, 0]])
    # j0 turns 90 about z: j1 at (0, 1); j1 turns another 90: j2 at (0, 1) + (-1, 0)
    np.testing.assert_allclose(skeleton.positions(pose), [[0, 0, 0], [0, 1, 0], [-1, 1, 0]], atol=1e-12)
    # vectorized over leading axes: a batch of 5 identical poses gives 5 identical answers
    batch = Pose(
        rotations=np.broadcast_to(pose.rotations, (5, 3, 4)), translations=np.broadcast_to(pose.translations, (5, 3, 3))
    )
    np.testing.assert_allclose(skeleton.world(batch), np.broadcast_to(skeleton.world(pose), (5, 3, 4, 4)))


def fox_viewer_matrices(path, animation_name, times):
    """World matrices of every node at `times`, as a viewer computes them: pygltflib parses,
    scipy interpolates (Slerp) and composes."""
    import pygltflib

    gltf = pygltflib.GLTF2().load(str(path))
    blob = gltf.binary_blob()

    def accessor(index):
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        assert acc.componentType == 5126 and not view.byteStride
        return (
            np.frombuffer(blob, dtype=np.float32, count=acc.count * width, offset=start)
            .reshape(acc.count, width)
            .astype(float)
        )

    nodes = gltf.nodes
    t = {i: np.tile(n.translation or [0, 0, 0], (len(times), 1)).astype(float) for i, n in enumerate(nodes)}
    r = {i: Rotation.from_quat(np.tile(n.rotation or [0, 0, 0, 1], (len(times), 1))) for i, n in enumerate(nodes)}
    s = {i: np.tile(n.scale or [1, 1, 1], (len(times), 1)).astype(float) for i, n in enumerate(nodes)}
    animation = next(a for a in gltf.animations if a.name == animation_name)
    for channel in animation.channels:
        sampler = animation.samplers[channel.sampler]
        keys, values = accessor(sampler.input)[:, 0], accessor(sampler.output)
        clipped = np.clip(times, keys[0], keys[-1])
        if channel.target.path == "rotation":
            r[channel.target.node] = Slerp(keys, Rotation.from_quat(values))(clipped)
        elif channel.target.path == "translation":
            t[channel.target.node] = np.stack([np.interp(clipped, keys, values[:, k]) for k in range(3)], axis=1)
    local = {}
    for i in range(len(nodes)):
        m = np.tile(np.eye(4), (len(times), 1, 1))
        m[:, :3, :3] = r[i].as_matrix() * s[i][:, None, :]
        m[:, :3, 3] = t[i]
        local[i] = m
    world = {}

    def visit(i, parent):
        world[i] = local[i] if parent is None else world[parent] @ local[i]
        for child in nodes[i].children or []:
            visit(child, i)

    for root in gltf.scenes[gltf.scene or 0].nodes:
        visit(root, None)
    return {(nodes[i].name or f"node {i}"): m for i, m in world.items()}


def test_fox_forward_kinematics_matches_a_viewers_joint_matrices(shared_data):
    path = shared_data / "fox-gltf" / "Fox.glb"
    clips = read_clips(path)
    assert sorted(clips) == ["Run", "Survey", "Walk"]
    survey = clips["Survey"]
    assert survey.fps == 24.0 and survey.n_frames == 83
    assert all(clip.skeleton is survey.skeleton for clip in clips.values())  # one skin, one skeleton
    frames = np.arange(0, survey.n_frames, 7)
    ours = survey.skeleton.world(survey.sample(frames / survey.fps))
    viewer = fox_viewer_matrices(path, "Survey", frames / survey.fps)
    for j, name in enumerate(survey.skeleton.names):
        np.testing.assert_allclose(ours[:, j], viewer[name], atol=1e-6, err_msg=name)
    # the clip moves: joints are not all at rest
    assert np.ptp(survey.skeleton.positions(survey.sample(np.linspace(0, survey.duration, 9))), axis=0).max() > 1


def bvh_positions_by_scipy(path, frames):
    """World joint positions of a BVH whose joints all list rotations Z Y X (this file), by regex
    and scipy: intrinsic rotations in the listed order, translation = OFFSET + position channels."""
    text = path.read_text()
    head, motion = text.split("MOTION")
    names, parents, offsets, channels, stack = [], [], [], [], []
    for line in head.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] in ("ROOT", "JOINT", "End"):
            names.append(words[1] if words[0] != "End" else None)
            parents.append(stack[-1] if stack else -1)
        elif words[0] == "{":
            stack.append(len(names) - 1)
        elif words[0] == "}":
            stack.pop()
        elif words[0] == "OFFSET":
            offsets.append([float(w) for w in words[1:4]])
        elif words[0] == "CHANNELS":
            channels.append((len(names) - 1, words[2:]))
    data = np.array(motion.split("\n", 3)[3].split(), dtype=float).reshape(-1, sum(len(c) for _, c in channels))[frames]
    rotations = [Rotation.identity(len(frames))] * len(names)
    translations = [np.tile(o, (len(frames), 1)) for o in offsets]
    column = 0
    for joint, names_ in channels:
        for k, channel in enumerate(names_):
            if channel.endswith("position"):
                translations[joint] = (
                    translations[joint] + np.eye(3)["XYZ".index(channel[0])] * data[:, column + k, None]
                )
        order = "".join(c[0] for c in names_ if c.endswith("rotation"))
        angles = data[:, [column + k for k, c in enumerate(names_) if c.endswith("rotation")]]
        rotations[joint] = Rotation.from_euler(order.upper(), angles, degrees=True)
        column += len(names_)
    world_r, world_p = [None] * len(names), [None] * len(names)
    for j, parent in enumerate(parents):
        if parent < 0:
            world_r[j], world_p[j] = rotations[j], translations[j]
        else:
            world_r[j] = world_r[parent] * rotations[j]
            world_p[j] = world_p[parent] + world_r[parent].apply(translations[j])
    return np.stack(world_p, axis=1), np.stack([r.as_matrix() for r in world_r], axis=1)


def test_bvh_forward_kinematics_matches_scipy(shared_data):
    path = shared_data / "cmu-mocap-bvh" / "01_01.bvh"
    clip = read_clips(path)["01_01"]
    assert clip.n_frames == 2752 and clip.fps == 120.0
    assert clip.skeleton.n_joints == 31 + 7  # 31 joints and 7 end sites
    frames = np.arange(0, 2752, 97)
    world = clip.skeleton.world(Pose(rotations=clip.rotations[frames], translations=clip.translations[frames]))
    positions, rotations = bvh_positions_by_scipy(path, frames)
    np.testing.assert_allclose(world[..., :3, 3], positions, atol=1e-6)
    np.testing.assert_allclose(world[..., :3, :3], rotations, atol=1e-6)


@pytest.mark.parametrize("order", ["XYZ", "YXZ", "ZXY"])
def test_bvh_channel_orders_and_position_channels(tmp_path, order):
    channels = " ".join(f"{a}rotation" for a in order)
    text = (
        "HIERARCHY\nROOT hips\n{\n OFFSET 1 2 3\n CHANNELS 6 Xposition Yposition Zposition " + channels + "\n"
        " JOINT arm\n {\n  OFFSET 0 5 0\n  CHANNELS 3 " + channels + "\n"
        "  End Site\n  {\n   OFFSET 0 2 0\n  }\n }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.04\n"
        "0 0 0 0 0 0 0 0 0\n10 20 30 15 -40 70 5 10 -20\n"
    )
    path = tmp_path / f"{order}.bvh"
    path.write_text(text)
    clip = read_clips(path)[order]
    assert clip.fps == 25.0 and clip.skeleton.names == ("hips", "arm", "arm_end")
    root = Rotation.from_euler(order, [15, -40, 70], degrees=True)
    arm = root * Rotation.from_euler(order, [5, 10, -20], degrees=True)
    expected = np.array([1, 2, 3]) + np.array([10, 20, 30])
    positions = clip.skeleton.positions(clip.pose(1))
    np.testing.assert_allclose(positions[0], expected, atol=1e-9)
    np.testing.assert_allclose(positions[1], expected + root.apply([0, 5, 0]), atol=1e-9)
    np.testing.assert_allclose(positions[2], positions[1] + arm.apply([0, 2, 0]), atol=1e-9)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "HIERARCHY\nROOT a\n{\n OFFSET 0 0\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n",
            "line 5: OFFSET needs 3 numbers",
        ),
        (
            "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 1 Wrotation\n}\nMOTION\n",
            "line 5: unknown channel 'Wrotation'",
        ),
        (
            "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 1 Xrotation\n}\nMOTION\nFrames: 3\nFrame Time: 0.1\n1\n2\n",
            "truncated",
        ),
        ("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n", "open"),
        ("hello", "not a BVH file"),
    ],
)
def test_malformed_bvh_files_are_refused_with_the_place(tmp_path, text, message):
    path = tmp_path / "bad.bvh"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=re.escape(message)) as error:
        read_clips(path)
    assert "bad.bvh" in str(error.value)


def test_glb_files_without_skin_and_truncated_are_refused(tmp_path, shared_data):
    with pytest.raises(ValidationError, match="no skin"):
        read_clips(shared_data / "morph-stress-test-gltf" / "MorphStressTest.gltf")
    truncated = tmp_path / "Fox.glb"
    truncated.write_bytes((shared_data / "fox-gltf" / "Fox.glb").read_bytes()[:5000])
    with pytest.raises(FileFormatError, match="Fox.glb"):
        read_clips(truncated)
    with pytest.raises(ValidationError, match="'.txt'"):
        read_clips(tmp_path / "clip.txt")


def test_clip_checks_its_fields():
    skeleton = chain(3)
    rotations = np.tile([0.0, 0, 0, 1], (4, 3, 1))
    good = {"skeleton": skeleton, "fps": 30, "rotations": rotations, "translations": np.zeros((4, 3))}
    clip = SkeletalClip(**good)
    np.testing.assert_array_equal(clip.translations[:, 1], np.tile([1.0, 0, 0], (4, 1)))  # rest kept
    # nearly unit quaternions (float32 files) are normalized; others refused, naming the entry
    nearly = good["rotations"] * 1.0004
    assert np.allclose(np.linalg.norm(SkeletalClip(**{**good, "rotations": nearly}).rotations, axis=-1), 1)
    far = good["rotations"].copy()
    far[2, 1] = [0, 0, 0, 2]
    with pytest.raises(ValidationError, match=r"SkeletalClip.rotations .* entry \(2, 1\) has length 2"):
        SkeletalClip(**{**good, "rotations": far})
    with pytest.raises(ValidationError, match=r"SkeletalClip.rotations must have shape \(T, 3, 4\)"):
        SkeletalClip(**{**good, "rotations": np.tile([0.0, 0, 0, 1], (4, 2, 1))})
    with pytest.raises(ValidationError, match="SkeletalClip.translations"):
        SkeletalClip(**{**good, "translations": np.zeros((4, 2))})
    with pytest.raises(ValidationError, match="SkeletalClip.fps"):
        SkeletalClip(**{**good, "fps": 0})
    with pytest.raises(ValidationError, match="past the clip's end"):
        SkeletalClip(**good, events=[Event(time=1.0, name="step")])
    with pytest.raises(ValidationError, match="parent must come before it"):
        Skeleton(names=["a", "b"], parents=[1, -1])
    with pytest.raises(ValidationError, match="'a' appear twice"):
        Skeleton(names=["a", "a"], parents=[-1, 0])


def test_sampling_a_clip_interpolates_on_the_sphere():
    skeleton = chain(2)
    turns = Rotation.from_euler("z", [[0], [90]], degrees=True).as_quat()
    clip = SkeletalClip(
        skeleton=skeleton, fps=1, rotations=np.stack([turns, turns], axis=1), translations=np.zeros((2, 3))
    )
    halfway = clip.sample([0.5]).rotations[0, 0]
    np.testing.assert_allclose(halfway, Rotation.from_euler("z", 45, degrees=True).as_quat(), atol=1e-12)
    np.testing.assert_allclose(clip.sample([-1, 5]).rotations[:, 0], turns, atol=1e-12)  # held at the ends
    assert flockkit.rigid.nlerp(turns[0], turns[1], 0.0) == pytest.approx(turns[0])
