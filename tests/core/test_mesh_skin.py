"""Skins on animated meshes: MeshSkin's checks, what read_mesh_animation reads of a glTF skin (on
the Fox and RobotExpressive, and on small files built here, damaged ones included), and what the
skin goes through (axes, saving, welding)."""

import numpy as np
import pytest

import flockkit
from flockkit.errors import FileFormatError, ValidationError
from flockkit.io import gltf
from flockkit.io.skin import read_skin

CHARACTERS = [("fox-gltf/Fox.glb", "Walk"), ("robot-expressive-gltf/RobotExpressive.glb", "Walking")]


def skin(**changes):
    fields = {"joint_names": ["root", "arm"], "parents": [-1, 0], "joints": [[0, 1], [1, 0], [0, 0]],
              "weights": [[0.5, 0.5], [1.0, 0.0], [0.25, 0.75]]}  # fmt: skip
    return flockkit.MeshSkin(**{**fields, **changes})


def test_a_skin_holds_its_joints_and_weights():
    made = skin()
    assert (made.n_vertices, made.n_joints) == (3, 2) and not made.weights.flags.writeable
    # a joint named twice for one vertex gets the sum of its weights
    assert np.allclose(made.weight_matrix(), [[0.5, 0.5], [0.0, 1.0], [1.0, 0.0]])
    assert made.dominant().tolist() == [0, 1, 0]  # a tie goes to the smaller joint
    assert made.take([2, 0]) == skin(joints=[[0, 0], [0, 1]], weights=[[0.25, 0.75], [0.5, 0.5]])
    assert made == skin() and made != skin(joint_names=["hips", "arm"])


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"joint_names": ["root"]}, "joint_names must be 2 distinct"),
        ({"joint_names": ["a", "a"]}, "joint_names must be 2 distinct"),
        ({"joint_names": "ab"}, "joint_names must be a sequence"),
        ({"parents": [1, -1]}, r"parents\[0\] = 1"),
        ({"joints": [[0, 2], [1, 0], [0, 0]]}, "must index the 2 joints"),
        ({"joints": [[0, -1], [1, 0], [0, 0]]}, "must index the 2 joints"),
        ({"joints": [[0.0, 1.0], [1, 0], [0, 0]]}, "joints must be an array of integers"),
        ({"weights": [[0.5, 0.5], [1.0, 0.0]]}, "must have the shape of joints"),
        ({"weights": [[0.5, 0.6], [1.0, 0.0], [0.25, 0.75]]}, "vertex 0's sum to 1.1"),
        ({"weights": [[1.5, -0.5], [1.0, 0.0], [0.25, 0.75]]}, "finite and >= 0"),
        ({"weights": [[np.nan, 1.0], [1.0, 0.0], [0.25, 0.75]]}, "finite and >= 0"),
    ],
)
def test_a_bad_skin_is_refused_by_name(changes, match):
    with pytest.raises(ValidationError, match=match):
        skin(**changes)


def test_a_mesh_keeps_its_skin_through_axes_and_files(tmp_path):
    motion = flockkit.Motion(positions=np.random.default_rng(0).normal(size=(4, 3, 3)), dt=0.1)
    mesh = flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]], skin=skin(), up_axis="y")
    assert mesh.to_flockkit_axes().skin == mesh.skin
    mesh.save(tmp_path / "mesh.npz")
    assert flockkit.AnimatedMesh.load(tmp_path / "mesh.npz") == mesh
    bare = flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]])
    bare.save(tmp_path / "bare.npz")
    assert flockkit.AnimatedMesh.load(tmp_path / "bare.npz").skin is None and bare != mesh
    with pytest.raises(ValidationError, match="the skin has 2 vertices but there are 3 points"):
        flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]], skin=skin().take([0, 1]))
    with pytest.raises(ValidationError, match="AnimatedMesh.skin must be a flockkit.mesh.MeshSkin"):
        flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]], skin={"joints": [0, 0, 0]})


def test_a_saved_skin_that_does_not_fit_is_refused(tmp_path):
    from flockkit import _npzfile

    motion = flockkit.Motion(positions=np.zeros((2, 3, 3)), dt=0.1)
    flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]], skin=skin()).save(tmp_path / "mesh.npz")
    arrays, header = _npzfile.read(tmp_path / "mesh.npz", kind="mesh", versions=(3,))
    arrays = {**arrays, "skin_joints": np.array([[0, 7], [1, 0], [0, 0]])}
    metadata = {k: v for k, v in header.items() if k not in ("kind", "version", "format", "flockkit")}
    _npzfile.write(tmp_path / "bad.npz", kind="mesh", version=3, arrays=arrays, metadata=metadata)
    with pytest.raises(FileFormatError, match="bad.npz: invalid animated mesh: .*must index the 2 joints"):
        flockkit.AnimatedMesh.load(tmp_path / "bad.npz")


@pytest.mark.parametrize("path, clip", CHARACTERS)
def test_a_skinned_character_is_read_with_its_skin(shared_data, path, clip):
    mesh = flockkit.io.read_mesh_animation(shared_data / path, clip=clip, fps=5)
    bound = read_skin(shared_data / path)
    skeleton = flockkit.io.read_clips(shared_data / path)[clip].skeleton
    assert mesh.skin.joint_names == bound.joint_names == skeleton.names
    assert np.array_equal(mesh.skin.parents, skeleton.parents)
    # the same influences as the bind-pose reader's, vertex for vertex
    assert np.allclose(mesh.skin.weight_matrix(), bound.weight_matrix())
    # and they say what moves together: the vertices a joint holds alone move as one rigid body
    positions = mesh.motion.positions
    alone = mesh.skin.weight_matrix().max(axis=1) > 1 - 1e-6
    for joint in np.unique(mesh.skin.dominant()[alone]):
        held = positions[:, alone & (mesh.skin.dominant() == joint)]
        centred = held - held.mean(axis=1, keepdims=True)
        turned = np.einsum("tij,tnj->tni", flockkit.rigid.kabsch(centred, centred[:1]), centred[:1])
        assert np.abs(turned - centred).max() < 1e-4 * np.ptp(positions), skeleton.names[joint]


def test_a_mesh_without_a_skin_reads_none(shared_data):
    mesh = flockkit.io.read_mesh_animation(shared_data / "morph-stress-test-gltf" / "MorphStressTest.gltf")
    assert mesh.skin is None


# -- small skinned files, whole and damaged --------------------------------------------------------


def _write(tmp_path, *, joints=((0, 1, 0, 0),) * 3, weights=((0.5, 0.5, 0, 0),) * 3, prop=False, name="s.glb"):
    """A triangle skinned by two joints (node 1 "hips", node 2 "arm", its child), a one-key
    animation; with `prop`, a second triangle on a node no joint carries."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    blobs = [positions.tobytes(), np.array(joints, dtype=np.uint8).tobytes(), np.array(weights, np.float32).tobytes(),
             np.array([0.0], np.float32).tobytes(), np.array([[0, 0, 0]], np.float32).tobytes()]  # fmt: skip
    offsets = np.cumsum([0] + [len(b) for b in blobs])
    views = [{"buffer": 0, "byteOffset": int(o), "byteLength": len(b)} for o, b in zip(offsets, blobs)]
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5121, "count": 3, "type": "VEC4"},
        {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5126, "count": 1, "type": "SCALAR", "min": [0], "max": [0]},
        {"bufferView": 4, "componentType": 5126, "count": 1, "type": "VEC3"},
    ]
    nodes = [{"mesh": 0, "skin": 0}, {"name": "hips", "children": [2]}, {"name": "arm", "translation": [0, 1, 0]}]
    meshes = [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}}]}]
    roots = [0, 1]
    if prop:
        meshes.append({"primitives": [{"attributes": {"POSITION": 0}}]})
        nodes.append({"mesh": 1})
        roots.append(3)
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}], "nodes": nodes, "meshes": meshes,
        "skins": [{"joints": [1, 2]}], "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": int(offsets[-1])}],
        "animations": [{"channels": [{"sampler": 0, "target": {"node": 2, "path": "translation"}}],
                        "samplers": [{"input": 3, "output": 4}]}],
    }  # fmt: skip
    path = tmp_path / name
    path.write_bytes(gltf.glb_bytes(document, b"".join(blobs)))
    return path


def test_a_small_skinned_file_is_read_with_its_skin(tmp_path):
    mesh = flockkit.io.read_mesh_animation(_write(tmp_path))
    assert mesh.skin == flockkit.MeshSkin(joint_names=["hips", "arm"], parents=[-1, 0], joints=[[0, 1, 0, 0]] * 3,
                                          weights=[[0.5, 0.5, 0, 0]] * 3)  # fmt: skip
    # weights that do not sum to 1 are normalized, as the specification asks of readers
    assert np.allclose(flockkit.io.read_mesh_animation(_write(tmp_path, weights=((2, 2, 0, 0),) * 3)).skin.weights,
                       [[0.5, 0.5, 0, 0]] * 3)  # fmt: skip


def test_a_mesh_no_skeleton_carries_leaves_the_file_without_a_skin(tmp_path):
    mesh = flockkit.io.read_mesh_animation(_write(tmp_path, prop=True))
    assert mesh.motion.n_agents == 6 and mesh.skin is None


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"joints": ((0, 9, 0, 0),) * 3}, r"JOINTS_0 refer to joint 9; skins\[0\] has 2"),
        ({"weights": ((0, 0, 0, 0),) * 3}, "WEIGHTS_0 give vertex 0 no weight"),
        ({"weights": ((1, -1, 0, 0),) * 3}, "WEIGHTS_0 hold negative weights"),
    ],
)
def test_a_damaged_skin_is_refused_naming_the_file_and_where(tmp_path, changes, match):
    with pytest.raises(FileFormatError, match=f"s.glb: meshes\\[0\\].primitives\\[0\\].attributes.{match}"):
        flockkit.io.read_mesh_animation(_write(tmp_path, **changes))
