"""Feature arrows (paper 002, 4.2) and scene constraints (5.2)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import ValidationError
from flockkit.scene import Arrow, FlowField, SelfMovement


def test_keyframes_turn_along_the_great_circle_and_grow_linearly():
    features = flockkit.Features.from_keyframes([(0.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 0.5])], n_frames=11, dt=0.1)
    angles = np.degrees(np.arctan2(features.vectors[:, 2], features.vectors[:, 0]))
    np.testing.assert_allclose(angles, np.linspace(0, 90, 11), atol=1e-9)  # evenly along the great circle
    np.testing.assert_allclose(features.lengths, np.linspace(1.0, 0.5, 11))
    np.testing.assert_allclose(features.vectors[:, 1], 0, atol=1e-12)  # stays in the plane of the two
    tau, phi, theta = features.spherical().T
    np.testing.assert_allclose(tau, features.lengths)
    np.testing.assert_allclose(theta, np.radians(90 - angles), atol=1e-9)
    np.testing.assert_allclose(phi[:-1], 0, atol=1e-9)


def test_a_dying_gust_keeps_its_heading_and_the_ends_are_held():
    features = flockkit.Features.from_keyframes([(0.5, [0.0, 0.8]), (1.0, [0.0, 0.0])], n_frames=21, dt=0.1)
    np.testing.assert_allclose(features.vectors[:6], [[0.0, 0.8]] * 6)  # held before the first keyframe
    np.testing.assert_allclose(features.vectors[7], [0.0, 0.8 * 0.6])
    np.testing.assert_allclose(features.vectors[10:], 0, atol=1e-12)


def test_features_from_a_moving_flock_need_no_annotation():
    motion = flockkit.simulate(n_agents=12, steps=80, seed=3)
    features = flockkit.Features.from_motion(motion)
    velocity = np.gradient(motion.center_of_mass(), motion.dt, axis=0)
    assert features.lengths.max() == pytest.approx(1.0)
    cosine = np.sum(features.vectors * velocity, axis=1) / (features.lengths * np.linalg.norm(velocity, axis=1))
    assert cosine.min() > 1 - 1e-9  # the heading of the center of mass
    still = flockkit.Features.from_motion(flockkit.Motion(positions=np.zeros((5, 3, 2)), dt=0.1))
    assert not still.vectors.any()


def test_the_flow_field_weights_are_the_papers_by_hand():
    """Three arrows; the object at (1, 1): d = (sqrt 2, sqrt 10, 3). The paper's weight of arrow k
    is (1/d_k) sum_j d_j / sum_t ((1/d_t) sum_j d_j)."""
    field = FlowField(arrows=[
        {"position": [0.0, 0.0], "keyframes": [(0.0, [1.0, 0.0])]},
        {"position": [4.0, 0.0], "keyframes": [(0.0, [0.0, 1.0]), (2.0, [0.0, -1.0])]},
        Arrow(position=[1.0, 4.0], keyframes=[(0.0, [-0.5, 0.0])]),
    ])  # fmt: skip
    d = np.array([np.sqrt(2), np.sqrt(10), 3.0])
    raw = (1 / d) * d.sum()
    expected = raw / raw.sum()
    np.testing.assert_allclose(field.weights([[1.0, 1.0]])[0], expected)
    target = field.targets([[1.0, 1.0]], [0.0, 2.0])
    np.testing.assert_allclose(target[0, 0], expected[0] * np.array([1, 0]) + expected[1] * np.array([0, 1])
                               + expected[2] * np.array([-0.5, 0]))  # fmt: skip
    np.testing.assert_allclose(target[1, 0, 1], -expected[1])  # arrow 1 turned over 2 s
    np.testing.assert_allclose(field.weights([[4.0, 0.0]])[0], [0, 1, 0])  # on an arrow: that arrow alone


@settings(max_examples=30, deadline=None)
@given(point=st.tuples(st.floats(-50, 50), st.floats(-50, 50)))
def test_flow_weights_sum_to_one_and_favour_the_nearest(point):
    field = FlowField(arrows=[{"position": [0.0, 0.0], "keyframes": [(0.0, [1.0, 0.0])]},
                              {"position": [10.0, 0.0], "keyframes": [(0.0, [0.0, 1.0])]}])  # fmt: skip
    weights = field.weights([point])[0]
    assert weights.sum() == pytest.approx(1.0) and np.all(weights >= 0)
    nearer = int(np.argmin([np.hypot(*point), np.hypot(point[0] - 10, point[1])]))
    assert weights[nearer] >= 0.5 - 1e-12


def test_self_movement_rides_on_its_object():
    move = SelfMovement(object=3, keyframes=[(0.0, [0.2, 0.0]), (4.0, [0.0, 1.0])])
    np.testing.assert_allclose(np.linalg.norm(move.targets([0.0, 2.0, 4.0]), axis=1), [0.2, 0.6, 1.0])


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: flockkit.Features.from_keyframes([(1.0, [1, 0]), (0.5, [0, 1])], n_frames=20, dt=0.1), "increase"),
        (lambda: flockkit.Features.from_keyframes([(3.0, [1, 0])], n_frames=20, dt=0.1), "within|lie in"),
        (lambda: flockkit.Features.from_keyframes([(0.0, [2, 0])], n_frames=20, dt=0.1), "normalized"),
        (lambda: flockkit.Features.from_keyframes([], n_frames=20, dt=0.1), "at least one"),
        (lambda: FlowField(arrows=[]), "non-empty"),
        (lambda: Arrow(position=[0, 0, 0], keyframes=[(0.0, [1, 0])]), "coordinates"),
        (lambda: SelfMovement(object=-1, keyframes=[(0.0, [1, 0])]), "object"),
        (lambda: flockkit.Features(vectors=np.ones((4, 2)), dt=0.1), "lengths in"),
    ],
)
def test_bad_arrows_are_named_errors(make, match):
    with pytest.raises(ValidationError, match=match):
        make()


def test_features_travel_with_the_layers(tmp_path):
    t = np.arange(40) / 20
    x = np.repeat(np.linspace(0, 9, 10)[None], 40, axis=0)
    z = np.where(x > 4.5, 0.5 * np.sin(2 * np.pi * t)[:, None], 0.0)
    strip = flockkit.Motion(positions=np.stack([x, np.zeros_like(x), z], axis=2), dt=1 / 20)
    wind = flockkit.Features.from_keyframes([(0.0, [1.0, 0.0, 0.0]), (1.5, [0.0, 1.0, 0.0])], n_frames=40, dt=1 / 20)
    layers = flockkit.build_layers(strip, features=wind, seed=0)
    layers.save(tmp_path / "strip.npz")
    assert flockkit.GraphLayers.load(tmp_path / "strip.npz").features == wind
    with pytest.raises(ValidationError, match="one arrow per source frame"):
        flockkit.build_layers(strip, features=flockkit.Features(vectors=np.zeros((3, 3)), dt=0.05), seed=0)
