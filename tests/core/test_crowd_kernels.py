"""The compiled reading of a numpy store (flockkit.crowd._kernels) against the array API path that a
GPU store takes (interpolate_entries, blend_entries), to float32 tolerance."""

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool, UniquePool
from flockkit.crowd._kernels import read_entries, world_matrices
from flockkit.crowd.pool import blend_entries
from flockkit.crowd.runtime import interpolate_entries
from flockkit.errors import ValidationError
from flockkit.testing import inputs, strategies

# float32 rounding of unit quaternions and translations up to 10 (the reference reorders nothing,
# the compiled loop contracts into multiply-adds and uses polynomial acos and sin)
TOLERANCE = 4e-6


def entries_of(pose) -> np.ndarray:
    out = np.zeros(pose.rotations.shape[:-1] + (12,), dtype=np.float32)
    out[..., 0:4], out[..., 4:7] = pose.rotations, pose.translations
    out[..., 7:10] = 1.0
    return out


def assert_same_entries(got, expected):
    """Equal to TOLERANCE, a rotation and its negation being one rotation (both paths return the
    same sign; the check says which differs if one ever does not)."""
    np.testing.assert_allclose(got[..., 4:], expected[..., 4:], atol=TOLERANCE)
    np.testing.assert_allclose(got[..., 0:4], expected[..., 0:4], atol=TOLERANCE)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    frames=strategies.poses(n_joints=5, batch=(4, 6)),
    flips=st.lists(st.booleans(), min_size=24, max_size=24),
    shares=st.lists(
        st.sampled_from([0.0, 0.25, 0.5, 0.999]) | st.floats(0, 1, exclude_max=True), min_size=12, max_size=12
    ),  # fmt: skip
    alphas=st.lists(st.sampled_from([-1.0, 0.0, 1.0, 0.5]) | st.floats(0, 1), min_size=6, max_size=6),
)
def test_one_pass_equals_interpolating_then_blending(frames, flips, shares, alphas):
    """Per part: the source between two frames, the target between two frames, blended by α
    (none, 0, 1, or between), any rotation in either hemisphere: what interpolate_entries and
    blend_entries give."""
    store = entries_of(frames).reshape(24, 5, 12)  # 24 poses: 4 per part (source newer, older, target ...)
    store[np.array(flips), :, 0:4] *= -1
    width = 5 * 12
    rows = np.arange(24, dtype=np.int64).reshape(6, 4) * width
    shares = np.array(shares, dtype=np.float32).reshape(6, 2)
    alphas = np.array(alphas, dtype=np.float32)
    a, a1, b, b1 = (store[k::4] for k in range(4))
    dots = [np.abs(np.sum(x[..., :4] * y[..., :4], -1)) for x, y in ((a, a1), (b, b1))]
    # where two rotations are a half turn apart both ways round are the shorter; rounding decides
    if min(d.min() for d in dots) < 1e-4:
        return
    source = np.where(shares[:, :1, None] > 0, interpolate_entries(a.copy(), a1, shares[:, 0]), a)
    target = np.where(shares[:, 1:, None] > 0, interpolate_entries(b.copy(), b1, shares[:, 1]), b)
    if np.abs(np.sum(source[..., :4] * target[..., :4], -1)).min() < 1e-4:
        return
    expected = np.where(alphas[:, None, None] < 0, source, blend_entries(source.copy(), target, np.maximum(alphas, 0)))
    out = np.empty((6, 5, 12), dtype=np.float32)
    read_entries(store.reshape(-1), np.zeros(0, np.float32), rows, np.zeros((6, 2), bool), shares, alphas,
                 np.arange(6), out)  # fmt: skip
    assert_same_entries(out, expected)
    # weights 0 and 1 give the source and the target as read, a frame read whole exactly
    np.testing.assert_array_equal(out[(alphas <= 0) & (shares[:, 0] == 0)], a[(alphas <= 0) & (shares[:, 0] == 0)])
    np.testing.assert_array_equal(out[(alphas >= 1) & (shares[:, 1] == 0)], b[(alphas >= 1) & (shares[:, 1] == 0)])


def test_reading_between_frames_is_the_slerp_within_float32():
    """The compiled slerp (polynomial angle and sinc, weights scaled to a unit result) against the
    slerp in float64, for frames 0 to a half turn apart (quaternions up to 90 degrees) and every
    share: within float32 rounding (measured 2.4e-7), with no special case at equal frames."""
    rng = np.random.default_rng(7)
    joints = 64
    axis = rng.normal(size=(joints, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    start = rng.normal(size=(joints, 4))
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    half = np.linspace(0, np.pi / 2, joints)  # half the angle between the frames' rotations
    half[1] = 1e-7
    turn = np.concatenate([axis * np.sin(half)[:, None], np.cos(half)[:, None]], axis=1)
    x, y, z, w = turn.T
    a, b, c, d = start.T
    end = np.stack([w * a + x * d + y * c - z * b, w * b - x * c + y * d + z * a,
                    w * c + x * b - y * a + z * d, w * d - x * a - y * b - z * c], axis=1)  # fmt: skip
    end[::2] *= -1  # the other hemisphere: read the shorter way round all the same
    store = np.zeros((2, joints, 12), np.float32)
    store[0, :, 0:4], store[1, :, 0:4] = start, end
    shares = np.linspace(0, 1, 9, dtype=np.float32)[1:]
    rows = np.tile(np.array([0, joints * 12, 0, 0], np.int64), (len(shares), 1))
    out = np.empty((len(shares), joints, 12), np.float32)
    read_entries(store.reshape(-1), np.zeros(0, np.float32), rows, np.zeros((len(shares), 2), bool),
                 np.stack([shares, np.zeros_like(shares)], axis=1), np.full(len(shares), -1, np.float32),
                 np.arange(len(shares)), out)  # fmt: skip
    q0, q1 = store[0, :, 0:4].astype(np.float64), store[1, :, 0:4].astype(np.float64)
    q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -q1, q1)
    theta = np.arccos(np.clip(np.sum(q0 * q1, axis=1), -1, 1))[None, :, None]
    t = shares.astype(np.float64)[:, None, None]
    safe = np.where(theta > 0, np.sin(theta), 1)
    expected = np.where(theta > 1e-9, (np.sin((1 - t) * theta) * q0 + np.sin(t * theta) * q1) / safe,
                        (1 - t) * q0 + t * q1)  # fmt: skip
    np.testing.assert_allclose(out[..., 0:4], expected, atol=1e-6)
    assert np.all(np.isfinite(out))


def seam_clip():
    """A looping clip whose last frame is far from its first: parts reading between frames across
    the loop slerp over the jump."""
    clip = inputs.random_clip(9, frames=20, seed=3)
    rotations = np.array(clip.rotations)
    rotations[-1] = -rotations[len(rotations) // 2]  # far from frame 0, and in the other hemisphere
    return flockkit.SkeletalClip(skeleton=clip.skeleton, fps=clip.fps, rotations=rotations,
                                 translations=clip.translations[:, 0] * 3, name="seam")  # fmt: skip


def awkward_crowd(xp=None):
    """Streams of one skeleton: a clip, the same clip with every rotation negated (the other
    hemisphere), a clip with a seam, a Stopped one; a unique slot; parts dilating (between two
    frames), blending, blending to a unique slot and steady."""
    clip = inputs.random_clip(9, frames=40, seed=1)
    flipped = flockkit.SkeletalClip(skeleton=clip.skeleton, fps=clip.fps, rotations=-np.array(clip.rotations),
                                    translations=clip.translations[:, 0], name="flipped")  # fmt: skip
    seam = seam_clip()
    seam = flockkit.SkeletalClip(skeleton=clip.skeleton, fps=seam.fps, rotations=seam.rotations,
                                 translations=seam.translations[:, 0], name="seam")  # fmt: skip
    play = lambda c, **p: flockkit.get("controller", "clip", clip=c, **p)  # noqa: E731
    pool = StreamPool(
        [
            Stream(controller=play(clip), history=24),
            Stream(controller=play(flipped, rate=0.9), history=30),
            Stream(controller=play(seam, rate=1.7), history=40),
            Stream(controller=play(clip, rate=1.2), history=30, default="Stopped"),
        ],
        fps=30,
        xp=xp,
    )
    unique = UniquePool(2, max_bones=12, fps=30)
    unique.set(1, play(flipped, rate=2.0))
    crowd = Crowd(pool, n_agents=60, clusters={"body": np.arange(60) % 3}, unique=unique, seed=2)
    crowd.transition_to_streamed(np.arange(0, 15), "body", 3, blend_time=0.4, time_to_dilate=1.0)
    crowd.transition_to_streamed(np.arange(15, 25), "body", 2, blend_time=0.3, time_to_dilate=0.5)
    crowd.transition_to_streamed(np.arange(25, 35), "body", 1, blend_time=0.5)
    crowd.transition_to_unique([40, 41], "body", 1, blend_time=0.2)
    return crowd


def test_the_compiled_path_reads_what_the_array_api_path_reads():
    """Over a run: steady parts, dilating parts between two frames (across a loop seam too), blends
    into either hemisphere and into a unique slot, at α 0 (the frame a blend starts) and on."""
    crowd = awkward_crowd()
    ids = np.arange(crowd.n_agents)
    seen_between = seen_seam = 0
    for frame in range(30):
        compiled = crowd._entries(ids, 0)
        reference = crowd._entries(ids, 0, compiled=False)
        assert_same_entries(compiled, reference)
        for lag in (1, 3):  # as matching_offsets reads them
            assert_same_entries(crowd._entries(ids, 0, lag), crowd._entries(ids, 0, lag, compiled=False))
        record = crowd.instance_buffer()[:, 0]
        between = (record["offset"] % 1 > 0) | ((record["blend_time"] > 0) & (record["target_offset"] % 1 > 0))
        seen_between += int(between.sum())
        seen_seam += int(np.sum(between & ((record["stream"] == 2) | (record["target"] == 2))))
        if frame == 0:
            np.testing.assert_array_equal(crowd.alphas("body")[:35], 0)
        crowd.update()
    assert seen_between > 100 and seen_seam > 20  # the cases were met


def test_world_poses_are_forward_kinematics_of_the_local_ones():
    crowd = awkward_crowd()
    for _ in range(5):
        crowd.update()
    skeleton = crowd.skeletons[0]
    local = crowd.poses(cluster="body")
    expected = skeleton.world(local, dtype=np.float64)
    world = crowd.poses(cluster="body", space="world")
    assert world.dtype == np.float32 and world.shape == (60, 9, 4, 4)
    np.testing.assert_allclose(world, expected, atol=5e-6 * np.abs(expected).max())


def test_out_is_written_and_returned_and_a_bad_one_is_refused():
    crowd = awkward_crowd()
    crowd.update()
    buffer = np.full((5, 9, 12), np.nan, dtype=np.float32)
    got = crowd.entries([1, 4, 7, 40, 50], "body", out=buffer)
    assert got is buffer
    np.testing.assert_array_equal(buffer, crowd.entries([1, 4, 7, 40, 50], "body"))
    pose = crowd.poses([1, 4, 7, 40, 50], "body", out=buffer)
    assert np.shares_memory(pose.rotations, buffer)
    matrices = np.empty((5, 9, 4, 4), dtype=np.float32)
    assert crowd.poses([1, 4, 7, 40, 50], "body", space="world", out=matrices) is matrices
    for bad in (np.empty((4, 9, 12), np.float32), np.empty((5, 9, 12)), np.empty((5, 12, 9), np.float32).T,
                [[0.0]]):  # fmt: skip
        with pytest.raises(ValidationError, match="out must be a C-contiguous, writeable float32"):
            crowd.entries([1, 4, 7, 40, 50], "body", out=bad)
    with pytest.raises(ValidationError, match=r"out must .* \(5, 9, 4, 4\)"):
        crowd.poses([1, 4, 7, 40, 50], "body", space="world", out=buffer)


def test_the_result_does_not_depend_on_the_number_of_threads():
    crowd = awkward_crowd()
    for _ in range(3):
        crowd.update()
    ids = np.arange(crowd.n_agents)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        alone = crowd._entries(ids, 0)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(crowd._entries(ids, 0), alone)


def test_world_matrices_of_a_root_only_skeleton_are_its_local_transforms():
    """The kernel on its own: one joint, no parent, scaled: T R S."""
    entries = np.zeros((1, 1, 12), np.float32)
    entries[0, 0, 0:4] = [0, 0, np.sin(0.5), np.cos(0.5)]  # a turn of 1 radian about z
    entries[0, 0, 4:7] = [1, 2, 3]
    out = np.empty((1, 1, 4, 4), np.float32)
    world_matrices(entries, np.array([-1]), np.array([[2.0, 2.0, 2.0]], np.float32), out)
    expected = np.eye(4)
    expected[:2, :2] = 2 * np.array([[np.cos(1), -np.sin(1)], [np.sin(1), np.cos(1)]])
    expected[2, 2], expected[:3, 3] = 2, [1, 2, 3]
    np.testing.assert_allclose(out[0, 0], expected, atol=1e-6)


def test_a_store_on_a_gpu_gives_the_poses_of_a_numpy_store():
    """CuPy where a GPU is present: the array API path on the device against the compiled path on
    the CPU, to float32 tolerance."""
    cupy = pytest.importorskip("cupy", reason="CuPy is not installed (pip install cupy-cuda12x where a GPU is)")
    try:
        found = cupy.cuda.runtime.getDeviceCount()
    except Exception as exc:  # noqa: BLE001 - CuPy without a driver
        pytest.skip(f"CuPy finds no GPU: {type(exc).__name__}: {exc}")
    if not found:
        pytest.skip("CuPy finds no GPU")

    def run(xp):
        crowd = awkward_crowd(xp)
        for _ in range(8):
            crowd.update()
        return crowd.entries(cluster="body")

    on_gpu = run(cupy)
    assert type(on_gpu).__module__.startswith("cupy")
    assert_same_entries(cupy.asnumpy(on_gpu), run(None))
