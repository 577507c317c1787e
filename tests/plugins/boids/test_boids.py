import numpy as np
import pytest
from flockkit_boids import Boids
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.errors import ValidationError


def unit(vectors):
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 0)


def sampled_impulses(motion):
    """The impulses forward drew, recovered from the recorded wander contributions."""
    wander = motion.channels["wander"]
    impulses = np.zeros_like(wander)
    impulses[1:-1] = wander[1:-1] - unit(wander[:-2])
    return impulses


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_agents=st.sampled_from([1, 7, 40, 90]),
    dims=st.sampled_from([2, 3]),
    cohesion=st.floats(0.0, 5.0),
    fov=st.floats(30.0, 360.0),
)
def test_plausibility_inverts_forward_exactly(seed, n_agents, dims, cohesion, fov):
    model = Boids(cohesion_weight=cohesion, field_of_view=fov)
    motion = flockkit.simulate(
        n_agents=n_agents, steps=40, dims=dims, seed=seed, cohesion_weight=cohesion, field_of_view=fov
    )
    np.testing.assert_allclose(model.wander_impulses(motion), sampled_impulses(motion), rtol=0, atol=1e-9)


def test_plausibility_is_the_paper_gaussian_of_the_impulses():
    model = Boids()
    motion = flockkit.simulate(n_agents=10, steps=20, seed=4)
    impulses = sampled_impulses(motion)
    sigma = model.wander_sigma
    expected = np.sum(-np.sum(impulses**2, axis=-1) / (2 * sigma**2) - np.log(sigma * np.sqrt(2 * np.pi)), axis=1)
    expected[[0, -1]] = 0.0
    np.testing.assert_allclose(model.log_plausibility(motion), expected, rtol=1e-9)


def test_wander_is_kept_as_a_channel_and_continues():
    model = Boids()
    first = model.forward(flockkit.random_flock(n_agents=5, rng=np.random.default_rng(1)), 10, np.random.default_rng(2))
    assert set(first.channels) == {"wander"}
    state = first.state(-1)
    second = model.forward(state, 10, np.random.default_rng(3))
    np.testing.assert_array_equal(second.channels["wander"][0], first.channels["wander"][-1])
    np.testing.assert_allclose(second.velocities()[0], first.velocities()[-1])


def test_dense_and_kdtree_neighbors_agree():
    start = flockkit.random_flock(n_agents=150, rng=np.random.default_rng(5))
    dense = Boids(kdtree_above=10_000).forward(start, 30, np.random.default_rng(6))
    tree = Boids(kdtree_above=0).forward(start, 30, np.random.default_rng(6))
    np.testing.assert_allclose(tree.positions, dense.positions, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("fov", [120.0, 300.0, 360.0])
def test_compiled_pair_loop_steers_as_the_kdtree_pairs_do(dims, fov):
    """The compiled loop over every pair of a frame (small flocks, many frames at once) and the
    cKDTree pair list (large flocks, a frame at a time) are two implementations of the rules: they
    agree on every frame, forward and backward, with a stationary agent that sees all round and
    agents closer than the separation radius."""
    motion = flockkit.simulate(n_agents=30, dims=dims, steps=25, seed=7)
    x = np.array(motion.positions[1:])
    v = np.diff(motion.positions, axis=0) / motion.dt
    v[4, 2] = 0.0
    x[6, 1] = x[6, 0] + 0.1  # inside the separation radius
    compiled, tree = Boids(field_of_view=fov), Boids(field_of_view=fov, kdtree_above=0)
    for perception in (1.0, -1.0):
        expected = np.stack([tree._steering(a, b, perception) for a, b in zip(x, v)])
        np.testing.assert_allclose(compiled._steering(x, v, perception), expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(compiled._steering(x[6], v[6], perception), expected[6], rtol=0, atol=1e-9)
    assert np.abs(expected).max() > 1.0


def test_backward_reverses_perception():
    """With a narrow field of view, the agent behind sees the one ahead going forward; backward,
    perception turns round, so the agent ahead sees the one behind."""
    model = Boids(field_of_view=90.0, separation_weight=0.0, alignment_weight=0.0, speed_weight=0.0)
    x = np.array([[0.0, 0.0], [1.0, 0.0]])
    v = np.array([[1.0, 0.0], [1.0, 0.0]])
    forward = model._steering(x, v, 1.0)
    backward = model._steering(x, v, -1.0)
    assert forward[0, 0] > 0 and not forward[1].any()
    assert backward[1, 0] < 0 and not backward[0].any()


@pytest.mark.parametrize("dims", [2, 3])
def test_backward_ends_at_the_final_state(dims):
    model = Boids()
    final = flockkit.random_flock(n_agents=12, dims=dims, rng=np.random.default_rng(7))
    motion = model.backward(final, 25, np.random.default_rng(8))
    assert motion.n_frames == 26
    np.testing.assert_array_equal(motion.positions[-1], final.positions)
    np.testing.assert_allclose(motion.velocities()[-1], final.velocities, atol=1e-12)


@pytest.mark.parametrize(
    "obstacle",
    [
        flockkit.Ball(center=[12.0, 0.0], radius=3.0),
        flockkit.Box(lower=[10.0, -4.0], upper=[14.0, 4.0]),
        flockkit.Polygon(vertices=[[10.0, -4.0], [14.0, 0.0], [10.0, 4.0]]),
    ],
    ids=["ball", "box", "polygon"],
)
def test_flock_steers_round_an_obstacle(obstacle):
    start = flockkit.State(
        positions=np.stack([np.zeros(5), np.linspace(-1, 1, 5)], axis=1), velocities=np.tile([1.0, 0.0], (5, 1))
    )
    free = Boids().forward(start, 250, np.random.default_rng(0))
    avoiding = Boids(obstacles=[obstacle]).forward(start, 250, np.random.default_rng(0))
    assert obstacle.signed_distance(free.positions).min() < 0  # without avoidance it flies through
    assert obstacle.signed_distance(avoiding.positions).min() > -0.3


def test_3d_obstacle():
    sphere = flockkit.Ball(center=[8.0, 0.0, 0.0], radius=2.0)
    start = flockkit.State(positions=np.zeros((1, 3)), velocities=[[1.0, 0.0, 0.0]])
    motion = Boids(obstacles=[sphere]).forward(start, 200, np.random.default_rng(1))
    assert sphere.signed_distance(motion.positions).min() > -0.3


@pytest.mark.parametrize(
    "params, name",
    [
        ({"cohesion_weight": -1.0}, "cohesion_weight"),
        ({"wander_weight": 0.0}, "wander_weight"),
        ({"field_of_view": 400.0}, "field_of_view"),
        ({"perception_radius": float("nan")}, "perception_radius"),
        ({"dt": "x"}, "dt"),
        ({"obstacles": ["wall"]}, "obstacles"),
        ({"kdtree_above": -3}, "kdtree_above"),
    ],
)
def test_bad_parameters_are_named(params, name):
    with pytest.raises(ValidationError, match=name):
        flockkit.get("behavior", "boids", **params)


def test_bad_calls():
    model = Boids(obstacles=[flockkit.Ball(center=[0, 0, 0], radius=1)])
    flat = flockkit.random_flock(n_agents=3, dims=2, rng=np.random.default_rng(0))
    with pytest.raises(ValidationError, match=r"obstacles\[0\] is 3D"):
        model.forward(flat, 3, np.random.default_rng(0))
    motion = Boids().forward(flat, 3, np.random.default_rng(0))
    with pytest.raises(ValidationError, match="dt"):
        Boids(dt=0.05).log_plausibility(motion)
    with pytest.raises(ValidationError, match="steps"):
        Boids().forward(flat, 2.5, np.random.default_rng(0))


def test_simulate_is_reproducible_and_validated():
    a = flockkit.simulate(n_agents=6, steps=15, seed=11)
    assert a == flockkit.simulate(n_agents=6, steps=15, seed=11)
    assert a != flockkit.simulate(n_agents=6, steps=15, seed=12)
    assert a.n_frames == 16 and a.dt == 0.1
    for kwargs, field in (
        ({"n_agents": 0, "steps": 5}, "n_agents"),
        ({"n_agents": 3, "steps": 0}, "steps"),
        ({"n_agents": 3, "steps": 5, "dims": 4}, "dims"),
        ({"n_agents": 3, "steps": 5, "dt": 0}, "dt"),
    ):
        with pytest.raises(ValidationError, match=field):
            flockkit.simulate(**kwargs)
    wrong = flockkit.random_flock(n_agents=4, rng=np.random.default_rng(0))
    with pytest.raises(ValidationError, match="initial state"):
        flockkit.simulate(n_agents=5, steps=3, initial=wrong)


def test_default_flock_stays_together():
    """The defaults give one flock at about the target speed (what the demo relies on)."""
    motion = flockkit.simulate(n_agents=30, steps=600, seed=3)
    last = motion.positions[-1]
    spread = np.linalg.norm(last - last.mean(axis=0), axis=1).max()
    speed = np.linalg.norm(motion.velocities()[-100:], axis=-1).mean()
    assert spread < 10 and 0.8 < speed < 1.3


def test_guided_agents_follow_their_paths_and_the_others_react():
    boids = flockkit.get("behavior", "boids")
    start = flockkit.random_flock(n_agents=6, rng=np.random.default_rng(2))
    path = start.positions[0] + np.outer(np.arange(31) * 0.1, [0.0, 2.0])  # agent 0 flies north at speed 2
    free = boids.forward(start, 30, np.random.default_rng(5))
    guided = boids.forward(start, 30, np.random.default_rng(5), guide={0: path})
    np.testing.assert_array_equal(guided.positions[1:, 0], path[1:])
    assert not np.allclose(guided.positions[:, 1:], free.positions[:, 1:])  # the others see it
    back = boids.backward(guided.state(-1), 30, np.random.default_rng(5), guide={0: path})
    np.testing.assert_array_equal(back.positions[:-1, 0], path[:-1])


@pytest.mark.parametrize("guide, match", [({9: np.zeros((11, 2))}, "agent indices"), ({0: np.zeros((5, 2))}, "shape")])
def test_bad_guides_are_named(guide, match):
    boids = flockkit.get("behavior", "boids")
    start = flockkit.random_flock(n_agents=3, rng=np.random.default_rng(0))
    with pytest.raises(ValidationError, match=match):
        boids.forward(start, 10, np.random.default_rng(0), guide=guide)


@pytest.mark.parametrize(
    "group_guide, match",
    [
        ([([0, 7], np.zeros((11, 2)))], "group_guide\\[0\\] agents"),
        ([([], np.zeros((11, 2)))], "group_guide\\[0\\] agents"),
        ([([0, 1], np.zeros((5, 2)))], "group_guide\\[0\\] path"),
        ([([0, 1], np.full((11, 2), np.nan))], "group_guide\\[0\\] path"),
        ([[0, 1, 2]], "group_guide\\[0\\] must be an \\(agents, path\\) pair"),
    ],
)
def test_bad_group_guides_are_named(group_guide, match):
    boids = flockkit.get("behavior", "boids")
    start = flockkit.random_flock(n_agents=3, rng=np.random.default_rng(0))
    with pytest.raises(ValidationError, match=match):
        boids.forward(start, 10, np.random.default_rng(0), group_guide=group_guide)


def test_no_group_guide_simulates_as_before():
    """Without a group guide the draws and arithmetic are those of a plain simulation."""
    boids = flockkit.get("behavior", "boids")
    start = flockkit.random_flock(n_agents=6, rng=np.random.default_rng(2))
    plain = boids.forward(start, 30, np.random.default_rng(5))
    assert plain == boids.forward(start, 30, np.random.default_rng(5), group_guide=[])
    steered = boids.forward(start, 30, np.random.default_rng(5), group_guide=[([0, 1, 2], np.zeros((31, 2)))])
    assert not np.allclose(steered.positions, plain.positions)
