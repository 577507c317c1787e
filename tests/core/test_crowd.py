"""The stream pool and the crowd runtime (paper 003, sections 4.1-4.5)."""

import gc
import tracemalloc

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool, UniquePool, equation_4, equation_5
from flockkit.crowd.pool import PREFETCH_FRAMES
from flockkit.crowd.runtime import MAX_DILATION_RATE
from flockkit.errors import ValidationError
from flockkit.testing import inputs

WALKER = inputs.walker()
J = WALKER.skeleton.n_joints
FPS = 30.0


def player(clip=WALKER, **params):
    return flockkit.get("controller", "clip", clip=clip, **params)


def as_float32(pose):
    return pose.rotations.astype(np.float32), pose.translations.astype(np.float32)


def make_crowd(n_agents=40, seed=0):
    pool = StreamPool(
        [
            Stream(controller=player(), history=20),
            Stream(controller=player(rate=1.5), history=40),
            Stream(controller=player(rate=0.7, start=0.3), history=30, default="Stopped"),
            Stream(controller=player(), history=20),  # the same controller as stream 0
        ],
        fps=FPS,
    )
    return pool, Crowd(pool, n_agents=n_agents, clusters={"body": np.arange(n_agents) % 2}, seed=seed)


def test_offset_k_reads_the_pose_written_k_frames_ago():
    controller = player(rate=1.3)
    pool = StreamPool([Stream(controller=controller, history=12)], fps=FPS)
    for _ in range(25):  # past one trip round the ring
        pool.advance()
    newest = pool.clock[0] - 1  # the frame number of the head
    for k in (0, 1, 5, 11):
        read = pool.read(0, k)
        expected = controller.pose([(newest - k) / FPS])[0]
        np.testing.assert_array_equal(read.rotations, expected.rotations.astype(np.float32))
        np.testing.assert_array_equal(read.translations, expected.translations.astype(np.float32))
    with pytest.raises(ValidationError, match="beyond stream 0's history of 12"):
        pool.read(0, 12)
    fresh = StreamPool([Stream(controller=controller, history=12)], fps=FPS)
    with pytest.raises(ValidationError, match="written 1 frames"):
        fresh.read(0, 3)
    with pytest.raises(ValidationError, match="unknown stream id 4"):
        pool.read(4, 0)


def dilating_crowd(history, n_agents=2000, seed=0):
    """A crowd on a Running walk, with a Stopped stream of `history` frames to dilate into."""
    pool = StreamPool(
        [
            Stream(controller=player(), history=20),
            Stream(controller=player(rate=0.7, start=0.3), history=history, default="Stopped"),
        ],
        fps=FPS,
    )
    return pool, Crowd(pool, n_agents=n_agents, clusters={"body": 0}, seed=seed)


@pytest.mark.parametrize(
    ("history", "time_to_dilate", "change_rate"),
    [
        (30, 2.0, 29 / 60),  # Listing 2's changeRate, (M_new - M) / (timeToDilate x fps), M_new = 29
        (60, 1.0, MAX_DILATION_RATE),  # Listing 2 would ask 59 / 30 = 1.97 frames per frame: capped
    ],
)
def test_dilation_spreads_parts_over_the_whole_history(history, time_to_dilate, change_rate):
    pool, crowd = dilating_crowd(history)
    movers = np.arange(crowd.n_agents)
    crowd.transition_to_streamed(movers, "body", 1, blend_time=0.2, time_to_dilate=time_to_dilate)
    assert pool.is_running(1)
    np.testing.assert_array_equal(crowd.offsets("body"), 0)  # the first frame reads the head
    targets = crowd.dilation_targets("body")
    assert targets.min() == 0 and targets.max() == history - 1  # M_new = history - 1
    duration = (history - 1) / change_rate  # frames until the farthest target is reached
    trace = []
    for _ in range(int(np.ceil(duration)) + 1):
        crowd.update()
        trace.append(crowd.offsets("body"))
    trace = np.array(trace)
    steps = np.diff(np.vstack([np.zeros(len(movers)), trace]), axis=0)
    assert steps.min() >= 0 and steps.max() <= change_rate + 1e-5  # never faster than changeRate
    # each part moves at changeRate x target / M_new: all arrive together, spread all the way
    expected = np.minimum(np.arange(1, len(trace) + 1)[:, None] / duration, 1) * targets
    np.testing.assert_allclose(trace, expected, atol=1e-3)
    np.testing.assert_array_equal(trace[-1], targets)
    assert np.all(np.isnan(crowd.dilation_targets("body")))
    used = len(np.unique(trace[-1])) / history  # share of the history's frames some part reads
    reach = trace[-1].max() / (history - 1)
    print(f"history {history}, time_to_dilate {time_to_dilate} s: {used:.0%} of the history's frames read, "
          f"farthest offset {reach:.0%} of it, after {duration / FPS:.2f} s")  # fmt: skip
    assert used >= 0.9 and reach >= 0.9
    assert crowd.synchrony("body") < 2 / history  # about 1 / history of pairs read one frame


def spinner(seconds=2.0):
    """A clip whose second joint turns about z at a steady speed, a full turn per loop: any two
    moments of it differ, by an angle proportional to the time between them."""
    skeleton = flockkit.Skeleton(names=["root", "spinner"], parents=[-1, 0])
    angles = np.linspace(0, 2 * np.pi, int(seconds * FPS) + 1)
    rotations = np.zeros((len(angles), 2, 4))
    rotations[:, 0, 3] = 1
    rotations[:, 1, 2], rotations[:, 1, 3] = np.sin(angles / 2), np.cos(angles / 2)
    translations = np.zeros((len(angles), 3))
    return flockkit.SkeletalClip(skeleton=skeleton, fps=FPS, rotations=rotations, translations=translations)


@pytest.mark.parametrize(("history", "time_to_dilate"), [(30, 2.0), (60, 1.0), (60, None)])
def test_no_part_holds_a_pose_while_it_dilates(history, time_to_dilate):
    """Every frame of a dilation shows each part a new pose, at least (1 - MAX_DILATION_RATE) of a
    stream frame's motion on: offsets move by fractions of a frame and parts read between frames.
    Measured on a joint that turns steadily (a swinging limb is still for a moment at each end of
    its swing, whatever reads it)."""
    clip = spinner()
    slower = Stream(controller=player(clip, rate=0.7), history=history, default="Stopped")
    pool = StreamPool([Stream(controller=player(clip), history=20), slower], fps=FPS)
    crowd = Crowd(pool, n_agents=300, clusters={"body": 0}, seed=0)
    crowd.transition_to_streamed(np.arange(300), "body", 1, blend_time=1 / FPS, time_to_dilate=time_to_dilate)
    per_frame = 0.7 * 2 * np.pi / (2.0 * FPS)  # the stream's turn per frame
    before = crowd.poses(cluster="body").rotations[:, 1].astype(np.float64)
    turns, between = [], 0
    while not np.all(np.isnan(crowd.dilation_targets("body"))):
        crowd.update()
        assert np.all(np.isnan(crowd.alphas("body")))  # the blend took one frame: dilation alone
        now = crowd.poses(cluster="body").rotations[:, 1].astype(np.float64)
        turns.append(2 * np.arccos(np.minimum(np.abs(np.sum(now * before, axis=-1)), 1)))
        offsets = crowd.offsets("body")
        between += int(np.sum(offsets != np.floor(offsets)))
        before = now
    turns = np.array(turns) / per_frame  # stream frames played per crowd frame
    print(f"{turns.size} (frame, part) pairs while dilating, {between} read between frames: "
          f"{np.mean(turns < 1e-3):.1%} held their pose; slowest {turns.min():.3f} stream frames a frame")  # fmt: skip
    assert between > turns.size / 2
    assert turns.min() >= (1 - MAX_DILATION_RATE) - 1e-3  # never slower than half speed, never still


def test_a_part_between_two_frames_reads_the_slerp_between_them():
    pool, crowd = dilating_crowd(40, n_agents=50)
    crowd.transition_to_streamed(np.arange(50), "body", 1, blend_time=0.1, time_to_dilate=2.0)
    for _ in range(9):  # the blends are over: parts read their offsets alone
        crowd.update()
    offsets = crowd.offsets("body")
    between = np.flatnonzero(offsets != np.floor(offsets))
    assert len(between) > 30
    read = crowd.poses(between, "body")
    for part, got in zip(between, read):
        k, u = int(np.floor(offsets[part])), offsets[part] - np.floor(offsets[part])
        newer, older = pool.read(1, k), pool.read(1, k + 1)  # a frame behind the newer one
        cast = lambda p: flockkit.Pose(rotations=p.rotations.astype(np.float64), translations=p.translations)  # noqa: E731
        expected = flockkit.Pose.interpolate(cast(newer), cast(older), u)
        dots = np.abs(np.sum(got.rotations * expected.rotations, axis=-1))
        np.testing.assert_allclose(dots, 1, atol=1e-6)
        np.testing.assert_allclose(got.translations, expected.translations, atol=1e-6)


def test_blends_run_from_source_to_target_over_the_blend_time():
    pool, crowd = make_crowd()
    agents = np.array([1, 3, 5])  # on stream 1
    before = crowd.entries(agents, "body")
    source_offsets = crowd.offsets("body")[agents]
    crowd.transition_to_streamed(agents, "body", 0, blend_time=0.5, offsets=[2, 7, 11])
    np.testing.assert_array_equal(crowd.alphas("body")[agents], 0)
    np.testing.assert_array_equal(crowd.entries(agents, "body"), before)  # α = 0: the source at its offset
    alphas = []
    for _ in range(int(0.5 * FPS) - 1):
        crowd.update()
        alphas.append(crowd.alphas("body")[agents[0]])
        source = pool.gather(np.full(3, 1), source_offsets.astype(int), J)
        target = pool.gather(np.zeros(3, dtype=int), np.array([2, 7, 11]), J)
        mixed = crowd.entries(agents, "body")
        alpha = alphas[-1]
        np.testing.assert_allclose(
            mixed[..., 4:7], source[..., 4:7] + alpha * (target[..., 4:7] - source[..., 4:7]), atol=1e-6
        )
        np.testing.assert_allclose(np.linalg.norm(mixed[..., 0:4], axis=-1), 1, atol=1e-6)  # on the sphere
    np.testing.assert_allclose(alphas, np.arange(1, len(alphas) + 1) / (0.5 * FPS), atol=1e-5)
    with pytest.raises(ValidationError, match="dt"):
        crowd.update(dt=0)
    crowd.update()  # α reaches 1: the target at its offset, and the blend lands
    assert np.all(np.isnan(crowd.alphas("body")[agents]))
    target = pool.gather(np.zeros(3, dtype=int), np.array([2, 7, 11]), J)
    np.testing.assert_array_equal(crowd.entries(agents, "body"), target)
    assert crowd.instance_buffer()["stream"][agents, 0].tolist() == [0, 0, 0]


def test_blending_two_identical_streams_returns_that_stream():
    pool, crowd = make_crowd()
    agents = np.array([0, 2, 4, 6])  # on stream 0; stream 3 plays the same controller in step
    offsets = crowd.offsets("body")[agents].astype(int)
    crowd.transition_to_streamed(agents, "body", 3, blend_time=1.0, offsets=offsets)
    for _ in range(7):
        crowd.update()
        alone = pool.gather(np.zeros(4, dtype=int), offsets, J)
        np.testing.assert_allclose(crowd.entries(agents, "body"), alone, atol=1e-6)
        assert np.all(crowd.alphas("body")[agents] > 0)


def test_a_stream_stops_when_its_last_user_leaves_and_restarts_cleanly():
    pool, crowd = make_crowd()
    agents = np.arange(6)
    crowd.transition_to_streamed(agents, "body", 2, blend_time=0.1)
    assert pool.users[2] == 6 and pool.is_running(2)
    for _ in range(10):
        crowd.update()
    crowd.transition_to_streamed(agents[:3], "body", 0, blend_time=0.1)
    for _ in range(5):
        crowd.update()
    assert pool.users[2] == 3 and pool.is_running(2)
    crowd.transition_to_streamed(agents[3:], "body", 0, blend_time=0.1)
    assert pool.is_running(2)  # still read by the blends out of it
    for _ in range(5):
        crowd.update()
    assert pool.users[2] == 0 and not pool.is_running(2)
    assert pool.users.sum() == 40  # every part counted once, on the stream it reads
    crowd.transition_to_streamed([7], "body", 2, blend_time=0.1)  # restarts from its beginning
    assert pool.is_running(2) and pool.filled[2] == 1
    controller = pool.streams[2].controller
    np.testing.assert_array_equal(pool.read(2, 0).rotations, controller.pose([0.0]).rotations[0].astype(np.float32))


def held_bytes(pool) -> int:
    """Bytes of the distinct buffers of every numpy array reachable from the pool's attributes
    (views counted once, through the array that owns the memory), its streams excepted (the
    caller's controllers and clips)."""
    owners, stack = {}, [v for k, v in vars(pool).items() if k != "streams"]
    while stack:
        value = stack.pop()
        if isinstance(value, np.ndarray):
            while isinstance(value.base, np.ndarray):
                value = value.base
            owners[id(value)] = value
        elif isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, (list, tuple)):
            stack.extend(value)
    return sum(a.nbytes for a in owners.values())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_memory_counts_every_array_and_its_store_is_equation_5(seed):
    rng = np.random.default_rng(seed)
    clips = {j: inputs.random_clip(j, frames=10, seed=j) for j in (82, 25, 24)}
    bones = rng.choice([82, 25, 24], size=30)
    histories = rng.integers(20, 121, size=30)
    streams = [
        Stream(controller=player(clips[b]), history=int(h), default="Stopped" if k % 2 else "Running")
        for k, (b, h) in enumerate(zip(bones, histories))
    ]
    gc.collect()
    tracing = tracemalloc.is_tracing()
    if not tracing:
        tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        pool = StreamPool(streams)
        gc.collect()
        traced = tracemalloc.get_traced_memory()[0] - before  # what building the pool left allocated
    finally:
        if not tracing:
            tracemalloc.stop()
    parts = pool.memory_parts()
    assert parts["store"] == equation_5(bones, histories) == 48 * int(np.sum(bones * histories))
    assert parts["prefetch"] == 48 * PREFETCH_FRAMES * int(np.sum(bones[~pool.batched & ~pool.live]))
    assert parts["batch"] == sum(evaluator.nbytes for _, evaluator in pool._batches)
    assert pool.memory() == sum(parts.values()) == held_bytes(pool) + parts["batch"]
    # the rest of what building left behind is Python objects (dicts, array headers, events)
    assert pool.memory() <= traced <= pool.memory() + 64 * 1024
    extra = parts["prefetch"] / parts["store"]
    print(f"pool {pool.memory()} bytes, traced {traced}: Equation 5 {parts['store']}, prefetch {parts['prefetch']} "
          f"(+{extra:.0%}), bookkeeping {parts['bookkeeping']}")  # fmt: skip
    unique = UniquePool(7, max_bones=82)
    assert unique.memory() == equation_5(bones, histories, unique=7) - parts["store"] + 7 * 8  # and its clocks
    assert equation_4(bones, histories, transitions=4096) > equation_5(bones, histories)


def test_poses_local_and_world_agree_with_forward_kinematics():
    pool, crowd = make_crowd()
    for _ in range(3):
        crowd.update()
    local = crowd.poses([0, 1, 2], "body")
    world = crowd.poses([0, 1, 2], "body", space="world")
    expected = WALKER.skeleton.world(flockkit.Pose(rotations=local.rotations, translations=local.translations))
    np.testing.assert_allclose(world, expected, atol=1e-5)
    # a part reads its stream at its offset: agent 0 (stream 0) equals the pool's read
    offset = int(crowd.offsets("body")[0])
    np.testing.assert_array_equal(local.rotations[0], pool.read(0, offset).rotations)


def test_unique_slots_and_visibility():
    pool, crowd = make_crowd()
    unique = UniquePool(2, max_bones=J, fps=FPS)
    crowd = Crowd(pool, n_agents=10, clusters={"body": 0}, unique=unique, seed=0)
    unique.set(1, player(rate=2.0))
    crowd.transition_to_unique([4], "body", 1, blend_time=0.1)
    for _ in range(4):
        crowd.update()
    np.testing.assert_array_equal(crowd.entries([4], "body")[0, :, 0:4], unique.read(1).rotations)
    assert np.isnan(crowd.offsets("body")[4])
    crowd.set_visible([4, 5], "body", False)
    masks = crowd.instance_buffer()["mask"][:, 0]
    assert masks[4] == 0 and masks[5] == 0 and masks[6] == 1


def test_events_come_from_the_streams_that_play_them():
    pool = StreamPool([Stream(controller=player(), history=10)], fps=FPS)
    crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, seed=0)
    events = [e for _ in range(int(2 * FPS)) for e in crowd.update()]
    assert [e.event.name for e in events] == ["step", "step"]  # the walker steps twice a cycle
    assert all(e.stream == 0 and not e.unique for e in events)


def test_bad_input_is_refused_and_changes_nothing():
    pool, crowd = make_crowd()
    crowd.transition_to_streamed([0, 2], "body", 2, blend_time=0.3)
    before, users, running = crowd.instance_buffer().copy(), pool.users.copy(), pool.running.copy()
    other = StreamPool([Stream(controller=player(inputs.random_clip(7)), history=5)])
    odd = Crowd(other, n_agents=2, clusters={"arm": 0, "flag": [0, -1]})
    cases = [
        (lambda: crowd.transition_to_streamed([1, 99], "body", 0, 0.2), "unknown agent id 99"),
        (lambda: crowd.transition_to_streamed([1, 1], "body", 0, 0.2), "repeat an id; 1 is given twice"),
        (lambda: crowd.poses([3, 0, 3], "body"), "repeat an id; 3 is given twice"),
        (lambda: crowd.transition_to_streamed([1], "body", 9, 0.2), "unknown stream id 9"),
        (lambda: crowd.transition_to_streamed([1], "body", 0, 0.0), "blend_time"),
        (lambda: crowd.transition_to_streamed([1], "body", 0, -1), "blend_time"),
        (lambda: crowd.transition_to_streamed([1], "legs", 0, 0.2), "unknown cluster 'legs'"),
        (lambda: crowd.transition_to_streamed([1], "body", 0, 0.2, offsets=[25]), "offsets must be integers in 0..19"),
        (
            lambda: crowd.transition_to_streamed([1], "body", 0, 0.2, offsets=[0], time_to_dilate=1),
            "without time dilation",
        ),
        (lambda: crowd.transition_to_unique([1], "body", 0, 0.2), "no UniquePool"),
        (lambda: odd.transition_to_streamed([1], "flag", 0, 0.2), "agent 1 has no 'flag' cluster"),
        (lambda: odd.poses([0, 1], "flag"), "agent 1 has no 'flag' cluster"),
        (lambda: odd.poses(cluster="flag", out=np.empty((2, 7, 12), np.float32)), "agent 1 has no 'flag' cluster"),
        (lambda: crowd.poses([0], "body", space="screen"), "space"),
    ]
    for call, message in cases:
        with pytest.raises(ValidationError, match=message):
            call()
    np.testing.assert_array_equal(crowd.instance_buffer(), before)
    np.testing.assert_array_equal(pool.users, users)
    np.testing.assert_array_equal(pool.running, running)
    mixed = StreamPool(
        [Stream(controller=player(), history=5), Stream(controller=player(inputs.random_clip(7)), history=5)]
    )
    with pytest.raises(ValidationError, match="does not match"):
        Crowd(mixed, n_agents=4, clusters={"body": [0, 1, 0, 1]})
    crowd2 = Crowd(mixed, n_agents=2, clusters={"body": 0})
    with pytest.raises(ValidationError, match=r"stream 1's skeleton \(7 joints\) does not match cluster 'body'"):
        crowd2.transition_to_streamed([0], "body", 1, 0.2)
    with pytest.raises(ValidationError, match="Stream.history"):
        Stream(controller=player(), history=0)
    with pytest.raises(ValidationError, match="Stream.default"):
        Stream(controller=player(), history=3, default="Paused")
    with pytest.raises(ValidationError, match="Stream.controller"):
        Stream(controller="clip", history=3)


def test_sampling_and_blending_run_through_the_array_api_alone():
    """A store in array-api-strict (the standard and nothing more, as a GPU library's would be)
    gives the poses a numpy store gives: one code path for CPU and GPU."""
    strict = pytest.importorskip("array_api_strict", reason="pip install array-api-strict (in the test extra)")

    def run(xp):
        pool = StreamPool(
            [
                Stream(controller=player(), history=20),
                Stream(controller=player(rate=1.5), history=40),
                Stream(controller=player(rate=0.7, start=0.3), history=30, default="Stopped"),
            ],
            fps=FPS,
            xp=xp,
        )
        unique = UniquePool(1, max_bones=J, fps=FPS)
        unique.set(0, player(rate=2.0))
        crowd = Crowd(pool, n_agents=30, clusters={"body": np.arange(30) % 2}, unique=unique, seed=4)
        crowd.transition_to_streamed(np.arange(0, 12), "body", 2, blend_time=0.4)
        crowd.transition_to_unique([13], "body", 0, blend_time=0.2)
        for _ in range(5):
            crowd.update()
        return crowd.poses(cluster="body"), crowd.alphas("body")

    reference, alphas = run(None)
    assert np.sum(alphas > 0) == 13  # blending, steady and unique parts all read
    strict_pose, _ = run(strict)
    assert strict_pose.rotations.__array_namespace__() is strict
    np.testing.assert_allclose(np.asarray(strict_pose.rotations), reference.rotations, atol=1e-6)
    np.testing.assert_allclose(np.asarray(strict_pose.translations), reference.translations, atol=1e-6)


@pytest.mark.parametrize("lag", [0, 1, 3, 50])
def test_the_compiled_reading_finds_what_the_array_api_path_reads(lag):
    """Where each part reads, found by the compiled pass over the instance records (store rows
    either side of a dilating offset, `lag` frames older up to the oldest frame held, unique
    slots, blend weights), against the array API path's numpy gathers: the same poses to float32
    rounding, for parts steady, dilating, blending into streams and into a unique slot."""
    pool = StreamPool(
        [
            Stream(controller=player(), history=20),
            Stream(controller=player(rate=1.5), history=40),
            Stream(controller=player(rate=0.7, start=0.3), history=30, default="Stopped"),
        ],
        fps=FPS,
    )
    unique = UniquePool(2, max_bones=J, fps=FPS)
    unique.set(1, player(rate=2.0))
    crowd = Crowd(pool, n_agents=30, clusters={"body": np.arange(30) % 2}, unique=unique, seed=4)
    for _ in range(6):
        crowd.update()
    crowd.transition_to_streamed(np.arange(0, 12), "body", 2, blend_time=0.4, time_to_dilate=1.0)
    crowd.transition_to_unique([13, 14], "body", 1, blend_time=0.2)
    for _ in range(4):
        crowd.update()
    ids = np.random.default_rng(lag).permutation(30)
    blending = crowd.alphas("body")[ids] > 0
    assert blending.sum() == 14 and (~blending).sum() == 16
    assert np.any(crowd.instance_buffer()["target_offset"][ids, 0] % 1 > 0)  # some read between two frames
    c = crowd.cluster_index("body")
    compiled, reference = crowd._entries(ids, c, lag), crowd._entries(ids, c, lag, compiled=False)
    np.testing.assert_allclose(compiled, reference, atol=2e-6)
