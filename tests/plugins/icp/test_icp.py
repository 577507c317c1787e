import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import ValidationError
from flockkit.testing import strategies as fst

from flockkit_icp import IcpHungarian


def random_rotation(dims, seed):
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((dims, dims)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def general_position(config):
    """Distinct principal spreads and no near-coincident agents: the copy has one best alignment."""
    centered = config.positions - config.center_of_mass()
    spreads = np.linalg.eigvalsh(centered.T @ centered)
    gaps = np.diff(spreads) / max(spreads[-1], 1e-12)
    close = np.linalg.norm(centered[:, None] - centered[None], axis=-1) + np.eye(len(centered)) * 1e9
    return spreads[0] > 1e-3 * spreads[-1] and gaps.min() > 0.05 and close.min() > 1e-2


@settings(max_examples=60, deadline=None)
@given(fst.configurations(min_agents=3, max_agents=12, max_coordinate=10.0), st.integers(0, 2**31), st.data())
def test_rigid_reordered_copies_are_found(config, seed, data):
    assume(general_position(config))
    rotation = random_rotation(config.dims, seed)
    order = np.array(data.draw(st.permutations(range(config.n_agents))))
    shift = np.random.default_rng(seed).normal(0, 20, config.dims)
    copy = flockkit.Configuration(positions=(config.positions @ rotation.T + shift)[order],
                                  velocities=(config.velocities @ rotation.T)[order])
    found = IcpHungarian().compare(config, copy)
    assert found.distance < 1e-9
    np.testing.assert_allclose(found.transform(copy.positions[found.assignment]), config.positions, atol=1e-6)
    np.testing.assert_allclose(found.rotation, rotation.T @ np.eye(config.dims), atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(fst.configurations(min_agents=1, max_agents=10), st.data())
def test_never_worse_than_the_configuration_frame_start(a, data):
    b = data.draw(fst.configurations(min_agents=a.n_agents, max_agents=a.n_agents, dims=a.dims))
    found = IcpHungarian(velocity_weight=0.0).compare(a, b)  # the paper's E
    start = a.frame().axes.T @ b.frame().axes
    moved = (b.positions - b.center_of_mass()) @ start.T + a.center_of_mass()
    start_distance = np.mean(np.sum((a.positions - moved) ** 2, axis=1))
    assert found.distance <= start_distance * (1 + 1e-9) + 1e-9
    assert np.linalg.det(found.rotation) == pytest.approx(1.0)
    assert found.distance == pytest.approx(found.residual(a, b), rel=1e-9, abs=1e-9)


@settings(max_examples=80, deadline=None)
@given(fst.configurations(min_agents=1, max_agents=10), st.data(), st.floats(0, 3))
def test_lower_bound_is_a_bound(a, data, weight):
    b = data.draw(fst.configurations(min_agents=a.n_agents, max_agents=a.n_agents, dims=a.dims))
    metric = IcpHungarian(velocity_weight=weight)
    distance = metric.compare(a, b).distance
    assert metric.lower_bound(a, b) <= distance * (1 + 1e-9) + 1e-9


def test_velocity_weight_adds_the_velocity_residual():
    motion = flockkit.simulate(n_agents=10, steps=60, seed=5)
    a, b = motion.configuration(10), motion.configuration(50)
    found = IcpHungarian(velocity_weight=0.7).compare(a, b)
    velocity_residual = np.mean(np.sum((a.velocities - b.velocities[found.assignment] @ found.rotation.T) ** 2, axis=1))
    assert found.distance == pytest.approx(found.residual(a, b) + 0.7 * velocity_residual, rel=1e-9)


def test_mirror_images_are_not_reflected():
    """A scalene triangle and its mirror image: a reflection would match them exactly."""
    corners = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 2.0]])
    triangle = flockkit.Configuration(positions=corners, velocities=np.zeros((3, 2)))
    mirror = flockkit.Configuration(positions=corners * [1.0, -1.0], velocities=np.zeros((3, 2)))
    found = IcpHungarian(velocity_weight=0.0).compare(triangle, mirror)
    assert np.linalg.det(found.rotation) == pytest.approx(1.0)
    # The true optimum over proper rotations, by brute force over the six assignments:
    from itertools import permutations

    from flockkit_icp.metric import _kabsch

    a, b = corners - corners.mean(axis=0), mirror.positions - mirror.center_of_mass()
    best = min(
        np.mean(np.sum((a - b[list(p)] @ _kabsch(b[list(p)], a).T) ** 2, axis=1)) for p in permutations(range(3))
    )
    assert found.distance == pytest.approx(best, rel=1e-9)
    assert best > 0.05  # whereas a reflection would match exactly


def test_real_fish_frames_match_better_when_close_in_time(shared_data):
    table = np.loadtxt(shared_data / "sticklebacks-5" / "ground_truth.csv", delimiter=",")
    fish = flockkit.Motion(positions=table[:, 1:].reshape(-1, 5, 2), dt=1 / 15)
    metric = IcpHungarian(velocity_weight=0.0)
    near = metric.compare(fish.configuration(100), fish.configuration(101)).distance
    far = metric.compare(fish.configuration(100), fish.configuration(250)).distance
    assert near < far


@pytest.mark.parametrize(
    "params, name",
    [({"velocity_weight": -1}, "velocity_weight"), ({"max_iterations": 0}, "max_iterations"), ({"tolerance": 0}, "tolerance")],
)
def test_bad_parameters(params, name):
    with pytest.raises(ValidationError, match=name):
        flockkit.get("metric", "icp-hungarian", **params)


@settings(max_examples=25, deadline=None)
@given(st.lists(fst.configurations(min_agents=4, max_agents=4, dims=2), min_size=2, max_size=5), st.floats(0, 2))
def test_batched_lower_bound_equals_the_pairwise_one(configs, weight):
    metric = IcpHungarian(velocity_weight=weight)
    matrix = metric.pairwise_lower_bound(configs)
    for i, a in enumerate(configs):
        for j, b in enumerate(configs):
            assert matrix[i, j] == pytest.approx(metric.lower_bound(a, b), rel=1e-9, abs=1e-9)
