"""The kit's skinned inputs: strategies.skinned_meshes draws valid skinned meshes whose vertices
are linear blend skinning of their joints, and inputs.chain_skin / inputs.limbs are what they say."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis.errors import InvalidArgument

import flockkit
from flockkit.testing import inputs
from flockkit.testing import strategies as fst


@settings(max_examples=40, deadline=None)
@given(fst.skinned_meshes(max_frames=5, max_joints=4, max_vertices=10, max_influences=3))
def test_skinned_meshes_are_valid_and_skinned(mesh):
    skin = mesh.skin
    assert isinstance(skin, flockkit.MeshSkin) and skin.n_vertices == mesh.motion.n_agents <= 10
    assert 1 <= skin.n_joints <= 4 and skin.joints.shape[1] <= 3 and 1 <= mesh.motion.n_frames <= 5
    assert np.all(skin.parents < np.arange(skin.n_joints)) and np.allclose(skin.weights.sum(axis=1), 1)
    assert len(mesh.faces) == 0 or mesh.faces.max() < mesh.motion.n_agents


@settings(max_examples=30, deadline=None)
@given(fst.skinned_meshes(max_influences=1))
def test_vertices_of_one_joint_move_as_one_rigid_body(mesh):
    """With one influence a vertex, each joint's vertices keep their distances in every frame."""
    positions = mesh.motion.positions
    for joint in np.unique(mesh.skin.dominant()):
        points = positions[:, mesh.skin.dominant() == joint]
        gaps = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)
        assert np.allclose(gaps, gaps[:1], atol=1e-6 * max(1.0, float(np.abs(positions).max())))


@pytest.mark.parametrize(
    "kwargs", [{"max_joints": 0}, {"min_frames": 3, "max_frames": 2}, {"max_influences": 0}, {"max_coordinate": 0}]
)
def test_bad_arguments_are_refused(kwargs):
    with pytest.raises(InvalidArgument):
        fst.skinned_meshes(**kwargs)


def test_chain_skin_puts_each_group_on_a_chain_of_its_own():
    motion, truth = inputs.parts()
    skin = inputs.chain_skin(motion.positions[0], truth)
    assert skin.joint_names == ("root", "group0.0", "group0.1", "group1.0", "group1.1", "group2.0", "group2.1")
    assert skin.parents.tolist() == [-1, 0, 1, 0, 3, 0, 5]
    owner = (skin.dominant() - 1) // 2  # the group of each vertex's dominant joint
    assert np.array_equal(owner, truth) and np.array_equal((skin.joints[:, 1] - 1) // 2, truth)
    assert np.allclose(skin.weights, [0.75, 0.25])
    lone = inputs.chain_skin(np.zeros((1, 3)), [0])
    assert lone.n_joints == 2 and lone.weights.tolist() == [[1.0, 0.0]]


def test_limbs_are_three_rigid_parts_moving_apart():
    mesh, truth = inputs.limbs()
    positions = mesh.motion.positions
    for part in range(3):
        points = positions[:, truth == part]
        gaps = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)
        assert np.allclose(gaps, gaps[:1], atol=1e-9)
    # a limb's far end changes its distance to the body
    far = np.argmax(np.abs(positions[0, truth == 1, 1]))
    body, limb = positions[:, truth == 0][:, 2], positions[:, truth == 1][:, far]  # body: at the other shoulder
    assert np.ptp(np.linalg.norm(body - limb, axis=-1)) > 0.2
    assert set(np.unique(mesh.skin.dominant()[truth == 1]).tolist()) == {4, 5}
