"""ica-kmeans on real data: MorphStressTest's morph targets are a ground truth of parts."""

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

import flockkit
import flockkit.testing.inputs
from flockkit.errors import ValidationError
from flockkit.io import gltf


@pytest.fixture(scope="module")
def morph(shared_data):
    path = shared_data / "morph-stress-test-gltf" / "MorphStressTest.gltf"
    document = gltf.Document(path)
    moved = []
    for primitive in document.json["meshes"][0]["primitives"]:
        offsets = np.stack([document.accessor(t["POSITION"]) for t in primitive["targets"]])
        moved.append(np.linalg.norm(offsets, axis=2) > 0)
    moved = np.concatenate(moved, axis=1)  # (targets, vertices)
    assert moved.sum(axis=0).max() == 1  # each vertex is moved by one target at most
    truth = np.where(moved.any(axis=0), moved.argmax(axis=0) + 1, 0)  # 0: never moved
    return flockkit.io.read_mesh_animation(path, clip="Individuals"), truth


def test_morph_targets_are_recovered_with_the_right_number_of_parts(morph):
    mesh, truth = morph
    parts = len(np.unique(truth))
    found = flockkit.segment(mesh, n_parts=parts, seed=0)
    assert found.n_parts == parts and adjusted_rand_score(truth, found.labels) >= 0.9


def test_the_number_of_parts_is_found(morph):
    mesh, truth = morph
    found = flockkit.segment(mesh, seed=0)
    assert found.n_parts == len(np.unique(truth)) == 9
    assert adjusted_rand_score(truth, found.labels) >= 0.9
    still = truth == 0
    assert len(np.unique(found.labels[still])) == 1 and not np.isin(found.labels[still], found.labels[~still]).any()


def test_a_motion_where_nothing_moves_is_one_part():
    still = flockkit.Motion(positions=np.zeros((20, 5, 3)), dt=0.1)
    assert flockkit.segment(still, seed=0).n_parts == 1


@pytest.mark.parametrize(
    "params, match",
    [({"n_parts": 50}, "more parts than the motion's 44 points"), ({"window": 40}, "too short for window=40"),
     ({"n_parts": 0}, "n_parts")],
)  # fmt: skip
def test_bad_requests_are_refused(params, match):
    motion, _ = flockkit.testing.inputs.parts()
    with pytest.raises(ValidationError, match=match):
        flockkit.segment(motion, seed=0, **params)


def test_a_segmentation_that_does_not_fit_is_refused(tmp_path):
    motion, truth = flockkit.testing.inputs.parts()
    found = flockkit.Segmentation(labels=truth, n_parts=3)
    found.save(tmp_path / "parts.npz")
    assert flockkit.Segmentation.load(tmp_path / "parts.npz") == found
    with pytest.raises(ValidationError, match="labels 44 points but the motion has 10"):
        found.check_fits(flockkit.Motion(positions=np.zeros((3, 10, 3)), dt=0.1))
    with pytest.raises(ValidationError, match="part 1 of 3 has no point"):
        flockkit.Segmentation(labels=[0, 2, 2], n_parts=3)
