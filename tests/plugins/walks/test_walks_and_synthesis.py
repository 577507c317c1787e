import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import flockkit
from flockkit.errors import ValidationError

FENCE = [
    flockkit.Ball(center=[15 * np.cos(a), 15 * np.sin(a)], radius=2.2)
    for a in np.linspace(0, 2 * np.pi, 24, endpoint=False)
]


@pytest.fixture(scope="module")
def recording():
    """Boids in an arena: a flock that turns, as region walks need (transitions keep the heading)."""
    return flockkit.simulate(n_agents=10, steps=600, seed=4, obstacles=FENCE)


@pytest.fixture(scope="module")
def graph(recording):
    return flockkit.build_graph(recording, seed=1, n_jobs=2)


@pytest.fixture(scope="module")
def fish(shared_data):
    motion = flockkit.io.read_wide(shared_data / "sticklebacks-5" / "ground_truth.csv", fps=15)
    return motion, flockkit.build_graph(motion, seed=0)


def largest_step(motion):
    return np.linalg.norm(np.diff(motion.positions, axis=0), axis=-1).max()


def nearest_neighbor_distance(motion, frames=None):
    positions = motion.positions if frames is None else motion.positions[frames]
    return np.mean([cKDTree(p).query(p, k=2)[0][:, 1].mean() for p in positions[::5]])


def polarization(motion, frames=None):
    velocities = motion.velocities()[:-1] if frames is None else motion.velocities()[frames]
    unit = velocities / np.maximum(np.linalg.norm(velocities, axis=-1, keepdims=True), 1e-12)
    return np.linalg.norm(unit.mean(axis=1), axis=-1).mean()


def com_box(source):
    """A box three times the extent of the source's center-of-mass path, around it."""
    com = source.center_of_mass()
    low, high = com.min(axis=0), com.max(axis=0)
    middle, half = (low + high) / 2, 1.5 * (high - low)
    return flockkit.Box(lower=middle - half, upper=middle + half)


def assert_quality(synthesized, source):
    """The quality bars: no jump beyond 1.5x the source's largest step, finite, N agents throughout."""
    assert np.isfinite(synthesized.positions).all() and synthesized.n_agents == source.n_agents
    assert largest_step(synthesized) <= 1.5 * largest_step(source)


def test_random_walks_meet_the_quality_bars(graph, recording):
    for seed in range(3):
        motion = flockkit.synthesize(graph, flockkit.walk(graph, duration=60, seed=seed))
        assert motion.duration >= 60
        assert_quality(motion, recording)
        assert nearest_neighbor_distance(motion) == pytest.approx(nearest_neighbor_distance(recording), rel=0.10)
        assert polarization(motion) == pytest.approx(polarization(recording), rel=0.10)


def test_region_walk_keeps_the_flock_in_the_box_for_five_minutes(graph, recording):
    box = com_box(recording)
    motion = flockkit.synthesize(graph, flockkit.walk(graph, strategy="region", region=box, duration=300, seed=2))
    assert motion.duration >= 300
    assert box.contains(motion.center_of_mass()).all()
    assert_quality(motion, recording)


def test_region_walk_checks_each_edge_it_takes_whole(recording):
    """Clips longer than the look-ahead are checked to their end, not only for `horizon` seconds
    (a graph without turns, whose clips are long)."""
    graph = flockkit.build_graph(recording, seed=1, n_jobs=2, turn_angle=0)
    box = com_box(recording)
    middle, half = (box.lower + box.upper) / 2, (box.upper - box.lower) / 4
    pen = flockkit.Box(lower=middle - half, upper=middle + half)
    assert (
        max(clip.stop - clip.start for clip in graph.clips) * graph.motion.dt > 10
    )  # clips far longer than the horizon
    for seed in (0, 2):
        motion = flockkit.synthesize(
            graph, flockkit.walk(graph, strategy="region", region=pen, duration=120, seed=seed, horizon=0.5)
        )
        assert pen.contains(motion.center_of_mass()).all()


@pytest.fixture(scope="module")
def default_flock():
    """The issue's case: a default flock (it barely turns: under 5 degrees a second) and its
    default graph."""
    recording = flockkit.simulate(n_agents=20, steps=1500, seed=0)
    return recording, flockkit.build_graph(recording, seed=0, n_jobs=2)


def start_box(recording, times=3.0, least=20.0):
    """A box centred on the group's start, its half-size `times` the flock's extent, at least `least`."""
    com = recording.center_of_mass()
    extent = np.linalg.norm(recording.positions - com[:, None], axis=-1).max()
    half = max(times * extent, least)
    return flockkit.Box(lower=com[0] - half, upper=com[0] + half)


def test_a_default_flock_is_kept_in_a_box_three_times_its_extent_for_five_minutes(default_flock):
    """Turns let the walk steer: every seed succeeds, the group roams the box (not one corner)
    and keeps the quality bars; without turns the same region is refused, and says why."""
    recording, graph = default_flock
    box = start_box(recording)
    half = (box.upper - box.lower) / 2
    for seed in range(3):
        motion = flockkit.synthesize(
            graph, flockkit.walk(graph, strategy="region", region=box, duration=300, seed=seed)
        )
        com = motion.center_of_mass()
        assert motion.duration >= 300 and box.contains(com).all()
        assert np.all(com.max(axis=0) - com.min(axis=0) > half)  # roams more than half the box each way
        assert_quality(motion, recording)
    plain = flockkit.build_graph(recording, seed=0, n_jobs=2, turn_angle=0)
    with pytest.raises(ValidationError, match="the graph has no turns") as info:
        flockkit.walk(plain, strategy="region", region=box, duration=300, seed=0)
    assert "tightest circle is about" in str(info.value) and "40 units across" in str(info.value)


def test_an_impossible_region_says_why_in_numbers(default_flock):
    """How far the group goes between transitions and how tight it turns, against the region's width."""
    recording, graph = default_flock
    com = recording.center_of_mass()
    blend = graph.transitions[0].blend
    travel = np.linalg.norm(com[blend:] - com[:-blend], axis=1).min()
    with pytest.raises(ValidationError) as info:
        flockkit.walk(
            graph, strategy="region", region=flockkit.Ball(center=[0.0, 0.0], radius=2.0), duration=60, seed=0
        )
    message = str(info.value)
    assert f"travels at least {travel:.3g} units" in message and "turns at most 15 degrees per transition" in message
    assert f"about {travel * 24 / np.pi:.3g} units across" in message and "region 4 units across" in message


def test_random_walks_take_turns_only_when_asked(default_flock):
    _, graph = default_flock

    def turns(walk):
        return sum(graph.transitions[i].is_turn for kind, i in walk.edges if kind == "transition")

    assert turns(flockkit.walk(graph, duration=120, seed=0)) == 0
    assert turns(flockkit.walk(graph, duration=120, seed=0, turns=True)) > 0


def test_sticklebacks(fish):
    source, graph = fish
    assert graph.stats()["transitions"] >= 3
    motion = flockkit.synthesize(graph, flockkit.walk(graph, duration=60, seed=0))
    assert_quality(motion, source)
    # The last 40% of this 20 s recording (the fish spread out) has no transition back, so the graph
    # trims it: synthesis can only reproduce the frames its clips keep, and is measured against them.
    kept_frames = np.unique(np.concatenate([np.arange(clip.start, clip.stop + 1) for clip in graph.clips]))
    assert nearest_neighbor_distance(motion) == pytest.approx(nearest_neighbor_distance(source, kept_frames), rel=0.10)
    assert polarization(motion) == pytest.approx(polarization(source, kept_frames), rel=0.10)
    box = com_box(source)
    kept = flockkit.synthesize(graph, flockkit.walk(graph, strategy="region", region=box, duration=300, seed=0))
    assert kept.duration >= 300 and box.contains(kept.center_of_mass()).all()
    assert_quality(kept, source)


def test_random_walk_is_deterministic_and_long_enough(graph):
    first = flockkit.walk(graph, duration=60, seed=5)
    assert first == flockkit.walk(graph, duration=60, seed=5)
    assert first != flockkit.walk(graph, duration=60, seed=6)
    motion = flockkit.synthesize(graph, first)
    assert motion.duration >= 60 and motion.n_agents == 10 and motion.dt == graph.motion.dt


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_synthesis_has_no_jumps(graph, recording, seed):
    assert_quality(flockkit.synthesize(graph, flockkit.walk(graph, duration=40, seed=seed)), recording)


def test_transition_keeps_world_positions_and_identities(graph):
    """Across a transition the group stays where it was, each agent near its own last position."""
    index, transition = next(
        (i, t) for i, t in enumerate(graph.transitions) if 0 < t.source and t.target < len(graph.clips)
    )
    edges = [("clip", k) for k in range(transition.source)] + [("transition", index), ("clip", transition.target)]
    motion = flockkit.synthesize(graph, flockkit.Walk(start=0, edges=edges))
    at = transition.start - graph.nodes[0]  # output frame where the transition happens
    jump = np.linalg.norm(motion.positions[at] - motion.positions[at - 1], axis=1)
    assert jump.max() <= 1.5 * largest_step(graph.motion)


def test_unblended_positional_transitions_would_jump():
    """Blends and the velocity term are what remove jumps: without them the same walks jump."""
    recording = flockkit.simulate(n_agents=6, steps=200, seed=11)
    rough = flockkit.build_graph(recording, seed=1, blend_time=0.0, metric_params={"velocity_weight": 0.0})
    worst = max(largest_step(flockkit.synthesize(rough, flockkit.walk(rough, duration=40, seed=s))) for s in range(5))
    assert worst > 1.5 * largest_step(recording)


def test_other_regions(graph):
    for region in (
        flockkit.Ball(center=[0.0, 0.0], radius=12.0),
        flockkit.Polygon(vertices=[[-13, -13], [13, -13], [13, 13], [0, 4], [-13, 13]]),
    ):
        motion = flockkit.synthesize(graph, flockkit.walk(graph, strategy="region", region=region, duration=60, seed=2))
        assert motion.duration >= 60 and region.contains(motion.center_of_mass()).all()


def test_impossible_region_is_an_error_not_a_loop(graph):
    with pytest.raises(ValidationError, match="region"):
        flockkit.walk(
            graph, strategy="region", region=flockkit.Ball(center=[0.0, 0.0], radius=0.3), duration=60, seed=0
        )
    with pytest.raises(ValidationError, match="3D"):
        flockkit.walk(graph, strategy="region", region=flockkit.Ball(center=[0.0, 0.0, 0.0], radius=5.0), duration=10)


def test_batch_synthesis(graph):
    walks = [flockkit.walk(graph, duration=20, seed=s) for s in range(50)]
    crowd = flockkit.synthesize_many(graph, walks)
    assert crowd.n_agents == 50 * 10 and crowd.n_frames == min(flockkit.synthesize(graph, w).n_frames for w in walks)
    np.testing.assert_array_equal(
        crowd.positions[:, 30:40], flockkit.synthesize(graph, walks[3]).positions[: crowd.n_frames]
    )
    with pytest.raises(ValidationError, match="n_frames"):
        flockkit.synthesize_many(graph, walks, n_frames=10**6)


def test_bad_walks_are_refused(graph):
    other = next(i for i, t in enumerate(graph.transitions) if t.source != 0)
    with pytest.raises(ValidationError, match="does not leave node 0"):
        flockkit.synthesize(graph, flockkit.Walk(start=0, edges=[("transition", other)]))
    first = next((i for i, t in enumerate(graph.transitions) if t.source == 0), None)
    if first is not None:
        target = graph.transitions[first].target
        at_target = next((i for i, t in enumerate(graph.transitions) if t.source == target), None)
        if at_target is not None:
            with pytest.raises(ValidationError, match="blend"):
                flockkit.synthesize(
                    graph, flockkit.Walk(start=0, edges=[("transition", first), ("transition", at_target)])
                )
    with pytest.raises(ValidationError, match="not an edge"):
        flockkit.synthesize(graph, flockkit.Walk(start=0, edges=[("clip", 10**6)]))
    with pytest.raises(ValidationError, match="Walk.start"):
        flockkit.synthesize(graph, flockkit.Walk(start=10**6, edges=[]))
    with pytest.raises(ValidationError):
        flockkit.Walk(start=0, edges=[("hop", 1)])
    with pytest.raises(ValidationError, match="duration"):
        flockkit.walk(graph, duration=-1)
    with pytest.raises(ValidationError, match="MotionGraph"):
        flockkit.get("walk", "random").walk("not a graph", np.random.default_rng(0), 10)


def test_build_graph_records_provenance(graph):
    assert graph.provenance["metric"] == "icp-hungarian" and graph.provenance["builder"] == "kovar"
    assert graph.provenance["seed"] == 1 and graph.provenance["flockkit"] == flockkit.__version__


def test_a_short_recording_is_kept_in_a_box_without_being_led_into_a_corner():
    """A minute of a default 20-boid flock, in a box 40 units across (about three of its
    tightest circles) for five minutes: the walk turns before the walls, away from corners
    (steered by where a point a little ahead lies, this walk ran into a corner 28 s in)."""
    recording = flockkit.simulate(n_agents=20, steps=600, seed=14)
    graph = flockkit.build_graph(recording, seed=14, n_jobs=1)
    start = recording.center_of_mass()[0]
    box = flockkit.Box(lower=start - 20, upper=start + 20)
    motion = flockkit.synthesize(graph, flockkit.walk(graph, strategy="region", region=box, duration=300, seed=14))
    assert motion.duration >= 300 and box.contains(motion.center_of_mass()).all()
    assert_quality(motion, recording)
