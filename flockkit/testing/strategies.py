"""Hypothesis strategies for flockkit values, in the style of ``hypothesis.extra.numpy``.

Arguments are keyword-only; bad arguments raise ``hypothesis.errors.InvalidArgument`` when the
strategy is created, not when it is drawn from::

    from hypothesis import given
    from flockkit.testing import strategies as fst

    @given(fst.motions(max_frames=30, dims=3))
    def test_something(motion): ...
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.extra import numpy as hnp

from .. import rigid
from ..constrained.problem import ComConstraint
from ..mesh import AnimatedMesh, MeshSkin
from ..motion import Alignment, Configuration, Motion, State
from ..scene.features import Features
from ..scene.segmentation import Segmentation
from ..skeleton import INTERPOLATIONS, Channel, Event, Pose, SkeletalClip, Skeleton

__all__ = [
    "configurations",
    "tied_configurations",
    "TIED_SHAPES",
    "symmetric_configurations",
    "configuration_lists",
    "index_pairs",
    "states",
    "motions",
    "frame_windows",
    "alignments",
    "com_tracks",
    "problems",
    "proposals",
    "proposal_contexts",
    "motion_graphs",
    "walks",
    "layered_walks",
    "features",
    "keyframed_arrows",
    "segmentations",
    "poses",
    "skeletons",
    "events",
    "skeletal_clips",
    "channels",
    "pose_times",
    "time_windows",
    "animated_meshes",
    "skinned_meshes",
    "guides",
    "group_guides",
    "regions",
    "declared_capabilities",
    "difference_matrices",
    "anything",
    "damaged",
]


def _check_count(name, value, low=1):
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InvalidArgument(f"{name} must be an integer >= {low}; got {value!r}")


def _check_range(low_name, low, high_name, high, floor=1):
    _check_count(low_name, low, floor)
    _check_count(high_name, high, floor)
    if low > high:
        raise InvalidArgument(f"{low_name}={low} must be <= {high_name}={high}")


def _check_positive(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InvalidArgument(f"{name} must be a finite number > 0; got {value!r}")


def _dims(dims):
    if dims is None:
        return st.sampled_from((2, 3))
    if dims not in (2, 3):
        raise InvalidArgument(f"dims must be 2, 3 or None (either); got {dims!r}")
    return st.just(dims)


def _names(name, value):
    names = tuple(value)
    for item in names:
        if not isinstance(item, str) or not item.isidentifier():
            raise InvalidArgument(f"{name} must hold Python identifiers; got {item!r}")
    return names


def _vectors(shape, bound):
    return hnp.arrays("float64", shape, elements=st.floats(-bound, bound, allow_nan=False, allow_infinity=False))


def _validate(min_agents, max_agents, max_coordinate, max_speed):
    _check_range("min_agents", min_agents, "max_agents", max_agents)
    _check_positive("max_coordinate", max_coordinate)
    _check_positive("max_speed", max_speed)


def configurations(*, min_agents=1, max_agents=10, dims=None, max_coordinate=100.0, max_speed=10.0, degenerate=False):
    """Configurations with N in [min_agents, max_agents], D = `dims` (None: 2 or 3), coordinates
    in [-max_coordinate, max_coordinate] and velocity components in [-max_speed, max_speed].

    With ``degenerate=True``, also the tied and symmetric ones of :func:`tied_configurations`
    (within the same bounds), which random coordinates almost never produce."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    if not isinstance(degenerate, bool):
        raise InvalidArgument(f"degenerate must be True or False; got {degenerate!r}")
    dims_strategy = _dims(dims)

    @st.composite
    def draw_configuration(draw):
        shape = (draw(st.integers(min_agents, max_agents)), draw(dims_strategy))
        return Configuration(
            positions=draw(_vectors(shape, max_coordinate)), velocities=draw(_vectors(shape, max_speed))
        )

    if not degenerate:
        return draw_configuration()
    tied = tied_configurations(
        dims=dims, min_agents=min_agents, max_agents=max_agents, max_coordinate=max_coordinate, max_speed=max_speed
    )
    return st.one_of(draw_configuration(), tied)


def states(*, min_agents=1, max_agents=10, dims=None, max_coordinate=100.0, max_speed=10.0, extra=()):
    """States as in :func:`configurations`, with one (N, D) array per name in `extra`, its
    components in [-max_speed, max_speed]."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    names = _names("extra", extra)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_state(draw):
        shape = (draw(st.integers(min_agents, max_agents)), draw(dims_strategy))
        return State(
            positions=draw(_vectors(shape, max_coordinate)),
            velocities=draw(_vectors(shape, max_speed)),
            extra={name: draw(_vectors(shape, max_speed)) for name in names},
        )

    return draw_state()


def motions(
    *,
    min_frames=1,
    max_frames=20,
    min_agents=1,
    max_agents=10,
    dims=None,
    dt=None,
    max_coordinate=100.0,
    channels=(),
):
    """Motions with T in [min_frames, max_frames], N in [min_agents, max_agents], D = `dims`
    (None: 2 or 3), coordinates in [-max_coordinate, max_coordinate], `dt` seconds per frame
    (None: drawn from [0.01, 1]) and one channel per name in `channels`."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _validate(min_agents, max_agents, max_coordinate, 1.0)
    if dt is not None:
        _check_positive("dt", dt)
    names = _names("channels", channels)
    dims_strategy = _dims(dims)
    dt_strategy = st.just(float(dt)) if dt is not None else st.floats(0.01, 1.0)

    @st.composite
    def draw_motion(draw):
        shape = (
            draw(st.integers(min_frames, max_frames)),
            draw(st.integers(min_agents, max_agents)),
            draw(dims_strategy),
        )
        return Motion(
            positions=draw(_vectors(shape, max_coordinate)),
            dt=draw(dt_strategy),
            channels={name: draw(_vectors(shape, max_coordinate)) for name in names},
        )

    return draw_motion()


def com_tracks(*, min_constraints=2, max_constraints=5, dims=None, max_coordinate=10.0, max_gap=3.0):
    """Tracks of center-of-mass constraints on all agents, as ``Problem.tracks`` holds them: a
    tuple of `min_constraints` to `max_constraints` ComConstraints in time order, the first at
    time 0, each the one before plus a gap in [0.5, max_gap] seconds (whole tenths, so that no two
    share a frame at the paper's 10 Hz), positions in [-max_coordinate, max_coordinate] and D =
    `dims` (None: 2 or 3)."""
    _check_range("min_constraints", min_constraints, "max_constraints", max_constraints)
    _check_positive("max_coordinate", max_coordinate)
    _check_positive("max_gap", max_gap)
    if max_gap < 0.5:
        raise InvalidArgument(f"max_gap must be >= 0.5 seconds; got {max_gap!r}")
    dims_strategy = _dims(dims)

    @st.composite
    def draw_track(draw):
        count, dims = draw(st.integers(min_constraints, max_constraints)), draw(dims_strategy)
        gaps = draw(st.lists(st.integers(5, int(max_gap * 10)), min_size=count - 1, max_size=count - 1))
        times = np.concatenate([[0], np.cumsum(gaps)]) / 10
        positions = draw(_vectors((count, dims), max_coordinate))
        return tuple(ComConstraint(time=float(t), position=p) for t, p in zip(times, positions))

    return draw_track()


def difference_matrices(*, max_size: int = 12):
    """Symmetric (K, K) difference matrices, K in [1, max_size], of a few distinct values (so that
    ties are common) with some cells +inf (not computed), as builders hold them."""
    _check_count("max_size", max_size)

    @st.composite
    def draw_matrix(draw):
        k = draw(st.integers(1, max_size))
        cells = draw(hnp.arrays("float64", (k, k), elements=st.sampled_from([0.0, 0.5, 1.0, 2.0, math.inf])))
        return np.minimum(cells, cells.T)

    return draw_matrix()


def anything(*, max_leaves: int = 4):
    """Values of every kind a careless caller passes where a number, an array or a component is
    expected: None, booleans, integers (huge and negative too), floats (NaN, infinities,
    subnormals, 1e308), strings, bytes, numpy arrays of odd shapes and dtypes, and lists (nested
    up to `max_leaves` values) of these. For robustness tests: a function given one must work or
    raise a documented flockkit error."""
    _check_count("max_leaves", max_leaves)
    scalars = st.one_of(
        st.none(),
        st.booleans(),
        st.integers(min_value=-(2**70), max_value=2**70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([0.0, -0.0, 5e-324, 1e308, -1e308, 1e-300, 2.0, 3.0]),
        st.text(max_size=6),
        st.binary(max_size=6),
    )
    arrays = hnp.arrays(
        dtype=st.sampled_from(["float64", "float32", "int64", "bool", "complex128"]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4),
    )
    return st.recursive(st.one_of(scalars, arrays), lambda inner: st.lists(inner, max_size=3), max_leaves=max_leaves)


def damaged(data: bytes, *, max_flips: int = 3):
    """Copies of the bytes `data` damaged as storage and transfers damage files: up to `max_flips`
    bytes changed, or cut short at any length, or both."""
    if not isinstance(data, bytes | bytearray) or not data:
        raise InvalidArgument(f"data must be non-empty bytes; got {type(data).__name__}")
    _check_count("max_flips", max_flips, low=0)
    size = len(data)

    @st.composite
    def draw_damaged(draw):
        damaged_data = bytearray(data)
        for _ in range(draw(st.integers(0, max_flips))):
            at = draw(st.integers(0, size - 1))
            damaged_data[at] ^= draw(st.integers(1, 255))
        if draw(st.booleans()):
            damaged_data = damaged_data[: draw(st.integers(0, size - 1))]
        return bytes(damaged_data)

    return draw_damaged()


# -- the other values a kind receives or returns -------------------------------------------------


# Quarter, half and eighth turns map squares, grids and regular polygons onto themselves (or
# nearly), so rotations take them as often as arbitrary angles.
_SPECIAL_ANGLES = (0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4)


def _angles(limit=math.pi):
    special = [a for a in _SPECIAL_ANGLES if abs(a) <= limit]
    return st.one_of(st.sampled_from(special), st.floats(-limit, limit))


def _rotations(dims):
    """Proper rotations (D, D) of any angle: in 2D one angle, in 3D yaw, pitch and roll (which
    reach every rotation), quarter and half turns among them; the identity where shrunk."""

    @st.composite
    def draw_rotation(draw):
        if dims == 2:
            return rigid.rotation(draw(_angles()))
        yaw, pitch, roll = draw(_angles()), draw(_angles(math.pi / 2)), draw(_angles())
        x, y, z = np.eye(3)
        return rigid.rotation(yaw, z) @ rigid.rotation(pitch, y) @ rigid.rotation(roll, x)

    return draw_rotation()


def alignments(*, n_agents=None, dims=None, max_translation=100.0, max_distance=100.0):
    """Alignments as a metric returns them: a proper rotation, a permutation of `n_agents` (None:
    1 to 10) agents, a translation in [-max_translation, max_translation] and a distance in
    [0, max_distance], in D = `dims` (None: 2 or 3)."""
    if n_agents is not None:
        _check_count("n_agents", n_agents)
    _check_positive("max_translation", max_translation)
    _check_positive("max_distance", max_distance)
    dims_strategy = _dims(dims)
    agents = st.just(n_agents) if n_agents is not None else st.integers(1, 10)

    @st.composite
    def draw_alignment(draw):
        n, d = draw(agents), draw(dims_strategy)
        return Alignment(
            distance=draw(st.floats(0.0, max_distance)),
            assignment=np.array(draw(st.permutations(range(n)))),
            rotation=draw(_rotations(d)),
            translation=draw(_vectors((d,), max_translation)),
        )

    return draw_alignment()


# The shapes of tied_configurations, and how many agents each can have (at least).
TIED_SHAPES = ("polygon", "hub", "grid", "spot", "pairs", "one", "line", "collinear")
_FEWEST = {"polygon": 3, "hub": 4, "spot": 2, "pairs": 2, "line": 2, "collinear": 2}
_MOVES = ("rest", "heading", "turning", "spreading")


def _counts(shape, d, low, high):
    """The numbers of agents in [low, high] that `shape` can have in `d` dimensions."""
    if shape == "one":
        return [1] if low <= 1 else []
    if shape == "grid":
        sizes, side = [], 2
        while side**d <= high:
            sizes += [side**d] if side**d >= low else []
            side += 1
        return sizes
    return list(range(max(low, _FEWEST[shape]), high + 1))


def _unit_shape(draw, shape, n, d):
    """`n` points of `shape` about the origin, the farthest at distance 1 (all 0 if coincident);
    flat shapes lie along the first axis or in the plane of the first two."""
    if shape in ("polygon", "hub"):
        k = n if shape == "polygon" else n - 1
        angle = np.arange(k) * 2 * math.pi / k
        points = np.zeros((n, d))
        points[:k, 0], points[:k, 1] = np.cos(angle), np.sin(angle)
        return points
    if shape == "grid":
        side = round(n ** (1 / d))
        points = np.stack(np.meshgrid(*[np.arange(float(side))] * d, indexing="ij"), axis=-1).reshape(-1, d)
    elif shape in ("spot", "one"):
        return np.zeros((n, d))
    elif shape == "pairs":  # n // 2 spots of two agents each, one of three if n is odd
        spots = draw(_vectors((n // 2, d), 1.0))
        points = spots[np.minimum(np.arange(n) // 2, n // 2 - 1)]
    elif shape == "line":
        points = np.outer(np.arange(float(n)), np.eye(d)[0])
    else:  # collinear: anywhere on one line, coincident agents allowed
        points = np.outer(draw(_vectors((n,), 1.0)), np.eye(d)[0])
    points = points - points.mean(axis=0)
    farthest = np.linalg.norm(points, axis=1).max()
    return points / farthest if farthest > 1e-12 else np.zeros_like(points)


def tied_configurations(
    *,
    dims=None,
    min_agents=1,
    max_agents=16,
    max_coordinate=10.0,
    max_radius=None,
    max_speed=2.0,
    shapes=TIED_SHAPES,
):
    """Degenerate configurations, which metrics and behavior models must handle and random
    coordinates almost never produce: tied distances, coincident agents, tied (zero) spreads that
    leave principal axes undefined. ``inputs.degenerate_configurations`` lists a fixed few of
    them; these are drawn, placed, turned and sized at random.

    Shapes (`shapes`, a subset of ``TIED_SHAPES``):

    - ``"polygon"``: a regular polygon of any number of corners;
    - ``"hub"``: a regular polygon with one more agent at its centre;
    - ``"grid"``: a square (2D) or cubic (3D) grid;
    - ``"spot"``: every agent on one spot;
    - ``"pairs"``: agents coincident two by two (one three if N is odd);
    - ``"one"``: a single agent;
    - ``"line"``: agents evenly spaced on a line;
    - ``"collinear"``: agents anywhere on one line.

    Each moves in one of four ways: at rest, all heading one way, turning rigidly about the
    centre, or spreading from (or gathering to) it. N in [min_agents, max_agents], D = `dims`
    (None: 2 or 3). The farthest agent lies at a radius in [max_radius / 100, max_radius]
    (default max_coordinate / 2) of the centre, every coordinate in [-max_coordinate,
    max_coordinate], and every velocity at most `max_speed` long. Distances tie up to rounding
    (a rotation by an arbitrary angle rounds them), as they do in real data."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    max_radius = max_coordinate / 2 if max_radius is None else max_radius
    _check_positive("max_radius", max_radius)
    if max_radius > max_coordinate:
        raise InvalidArgument(f"max_radius={max_radius} must be <= max_coordinate={max_coordinate}")
    if isinstance(shapes, str):
        raise InvalidArgument(f"shapes must be a collection of shape names, not one string; got {shapes!r}")
    shapes = tuple(shapes)
    unknown = [s for s in shapes if s not in TIED_SHAPES]
    if not shapes or unknown:
        raise InvalidArgument(f"shapes must be a non-empty subset of {TIED_SHAPES}; got {shapes!r}")
    _dims(dims)
    fitting = {
        d: [s for s in shapes if _counts(s, d, min_agents, max_agents)] for d in ((2, 3) if dims is None else (dims,))
    }
    fitting = {d: found for d, found in fitting.items() if found}
    if not fitting:
        raise InvalidArgument(f"no shape of {shapes} has between {min_agents} and {max_agents} agents in {dims}D")

    @st.composite
    def draw_degenerate(draw):
        d = draw(st.sampled_from(sorted(fitting)))
        shape = draw(st.sampled_from(fitting[d]))
        n = draw(st.sampled_from(_counts(shape, d, min_agents, max_agents)))
        unit = _unit_shape(draw, shape, n, d)
        radius = max_radius * draw(st.floats(0.01, 1.0))
        rotation = draw(_rotations(d))
        room = max_coordinate - radius
        centre = draw(_vectors((d,), room)) if room > 0 else np.zeros(d)
        positions = unit @ rotation.T * radius + centre
        speed = max_speed * draw(st.floats(0.0, 1.0))
        move = draw(st.sampled_from(_MOVES))
        if move == "rest":
            velocities = np.zeros_like(unit)
        elif move == "heading":
            velocities = np.tile(draw(_rotations(d))[:, 0] * speed, (n, 1))
        elif move == "turning":  # about the axis normal to the plane of the (turned) first two axes
            local = np.zeros_like(unit)
            local[:, 0], local[:, 1] = -unit[:, 1], unit[:, 0]
            velocities = local @ rotation.T * speed
        else:
            velocities = unit @ rotation.T * speed * draw(st.sampled_from([1.0, -1.0]))
        return Configuration(
            positions=np.clip(positions, -max_coordinate, max_coordinate),  # rounding, at most an ulp
            velocities=velocities,
        )

    return draw_degenerate()


def symmetric_configurations(*, dims=None, max_agents=16, max_coordinate=10.0):
    """:func:`tied_configurations` whose every agent ties with another: regular polygons,
    square (cubic) grids, agents on one spot, coincident pairs, one agent, evenly spaced agents on
    a line; N at most `max_agents` (>= 4), D = `dims` (None: 2 or 3), coordinates within
    `max_coordinate`. A rigid, reordered copy of one must be at distance 0 from it."""
    _check_count("max_agents", max_agents, low=4)
    return tied_configurations(
        dims=dims,
        max_agents=max_agents,
        max_coordinate=max_coordinate,
        shapes=("polygon", "grid", "spot", "pairs", "one", "line"),
    )


def _unit_quaternions(shape):
    @st.composite
    def draw_quaternions(draw):
        raw = draw(hnp.arrays("float64", (*shape, 4), elements=st.floats(-1, 1)))
        raw[..., 3] += 2.0  # away from zero length
        return raw / np.linalg.norm(raw, axis=-1, keepdims=True)

    return draw_quaternions()


def poses(*, n_joints=None, batch=(), max_translation=10.0):
    """Poses of `n_joints` (None: 1 to 8) joints with leading axes `batch` (a shape): unit
    rotations (x, y, z, w) and translations in [-max_translation, max_translation]."""
    if n_joints is not None:
        _check_count("n_joints", n_joints)
    batch = tuple(batch)
    for side in batch:
        _check_count("batch sides", side)
    _check_positive("max_translation", max_translation)
    joints = st.just(n_joints) if n_joints is not None else st.integers(1, 8)

    @st.composite
    def draw_pose(draw):
        j = draw(joints)
        return Pose(
            rotations=draw(_unit_quaternions((*batch, j))),
            translations=draw(_vectors((*batch, j, 3), max_translation)),
        )

    return draw_pose()


def skeletons(*, min_joints=1, max_joints=8):
    """Skeletons of J in [min_joints, max_joints] joints: a random tree (or forest) in which every
    parent comes before its children, unique joint names and a rest pose."""
    _check_range("min_joints", min_joints, "max_joints", max_joints)

    @st.composite
    def draw_skeleton(draw):
        j = draw(st.integers(min_joints, max_joints))
        parents = [-1] + [draw(st.integers(-1, k - 1)) for k in range(1, j)]
        return Skeleton(names=[f"joint{k}" for k in range(j)], parents=parents, rest=draw(poses(n_joints=j)))

    return draw_skeleton()


def events(*, max_time=10.0, names=("step", "cheer")):
    """Events at times in [0, max_time] seconds, named from `names`."""
    _check_positive("max_time", max_time)
    names = tuple(names)
    if not names or not all(isinstance(n, str) and n for n in names):
        raise InvalidArgument(f"names must hold non-empty strings; got {names!r}")
    return st.builds(Event, time=st.floats(0.0, max_time), name=st.sampled_from(names))


def skeletal_clips(*, min_joints=1, max_joints=6, min_frames=2, max_frames=30, fps=30.0, keys=("frames", "channels")):
    """Skeletal clips over a drawn skeleton, each keyed one of the ways in `keys`:

    - ``"frames"``: T in [min_frames, max_frames] frames at `fps`, unit rotations per frame and
      joint, translations of the roots alone (T, 3) or of every joint (T, J, 3);
    - ``"channels"``: :func:`channels` of some joints (rotations and translations, LINEAR, STEP
      or CUBICSPLINE, keys at uneven times; between min_frames and max_frames keys each), the
      clip sampled at `fps` for the tools that work on frames;

    and up to three events within the clip's duration (its ends included)."""
    _check_range("min_joints", min_joints, "max_joints", max_joints)
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _check_positive("fps", fps)
    keys = tuple(keys)
    if not keys or not set(keys) <= {"frames", "channels"}:
        raise InvalidArgument(f"keys must hold 'frames' and/or 'channels'; got {keys!r}")

    @st.composite
    def draw_clip(draw):
        skeleton = draw(skeletons(min_joints=min_joints, max_joints=max_joints))
        if draw(st.sampled_from(keys)) == "channels":
            keyed = draw(channels(skeleton, min_keys=min_frames, max_keys=max_frames, max_time=(max_frames - 1) / fps))
            content = {"channels": keyed}
            duration = max(float(c.times[-1]) for c in keyed)
        else:
            t = draw(st.integers(min_frames, max_frames))
            shape = draw(st.sampled_from([(t, 3), (t, skeleton.n_joints, 3)]))
            content = {
                "rotations": draw(_unit_quaternions((t, skeleton.n_joints))),
                "translations": draw(_vectors(shape, 10.0)),
            }
            duration = (t - 1) / fps
        times = st.one_of(st.sampled_from([0.0, duration]), st.floats(0.0, duration))
        tags = st.builds(Event, time=times, name=st.sampled_from(["step", "cheer"]))
        return SkeletalClip(
            skeleton=skeleton,
            fps=float(fps),
            events=draw(st.lists(tags, max_size=3)),
            name=draw(st.sampled_from(["walk", "idle", "run"])),
            **content,
        )

    return draw_clip()


def channels(skeleton, *, min_keys=2, max_keys=12, max_time=2.0, interpolations=INTERPOLATIONS):
    """Lists of :class:`flockkit.Channel` for `skeleton`: at least one, at most one per joint and
    path, the joints named or indexed; keys at strictly increasing, uneven times in [0, max_time]
    (the first at 0 or later), K in [min_keys, max_keys] per channel; unit quaternions for LINEAR
    and STEP rotations, any for CUBICSPLINE (with in and out tangents, as glTF keys them)."""
    if not isinstance(skeleton, Skeleton):
        raise InvalidArgument(f"skeleton must be a flockkit.Skeleton; got {type(skeleton).__name__}")
    _check_range("min_keys", min_keys, "max_keys", max_keys)
    _check_positive("max_time", max_time)
    interpolations = tuple(interpolations)
    if not interpolations or not set(interpolations) <= set(INTERPOLATIONS):
        raise InvalidArgument(f"interpolations must be among {INTERPOLATIONS}; got {interpolations!r}")

    @st.composite
    def draw_channel(draw, joint, path):
        k = draw(st.integers(min_keys, max_keys))
        gaps = draw(hnp.arrays("float64", k, elements=st.floats(0.05, 1.0)))
        first = draw(st.sampled_from([0.0, 0.1]))
        times = first + (max_time - first) * np.cumsum(gaps) / np.sum(gaps)
        times = np.concatenate([[first], times[:-1]]) if k > 1 else np.array([first])
        interpolation = draw(st.sampled_from(interpolations))
        width = 4 if path == "rotation" else 3
        if path == "rotation" and interpolation != "CUBICSPLINE":
            values = draw(_unit_quaternions((k,)))
        else:
            values = draw(_vectors((k, width), 2.0 if path == "rotation" else 10.0))
            if path == "rotation":
                values[:, 3] += 3.0  # away from the zero quaternion the spline would normalize
        tangents = {}
        if interpolation == "CUBICSPLINE":
            bound = 1.0 if path == "rotation" else 5.0  # rotations: the spline stays far from zero
            tangents = {side: draw(_vectors((k, width), bound)) for side in ("in_tangents", "out_tangents")}
        label = draw(st.sampled_from([joint, skeleton.names[joint]]))
        return Channel(joint=label, path=path, times=times, values=values, interpolation=interpolation, **tangents)

    @st.composite
    def draw_channels(draw):
        slots = [(j, path) for j in range(skeleton.n_joints) for path in ("rotation", "translation")]
        chosen = draw(st.lists(st.sampled_from(slots), min_size=1, max_size=min(len(slots), 6), unique=True))
        return [draw(draw_channel(j, path)) for j, path in chosen]

    return draw_channels()


def segmentations(*, min_points=1, max_points=20, max_parts=None):
    """Segmentations of N in [min_points, max_points] points into 1 to min(N, `max_parts`) parts,
    every part holding at least one point, labels in any order."""
    _check_range("min_points", min_points, "max_points", max_points)
    if max_parts is not None:
        _check_count("max_parts", max_parts)

    @st.composite
    def draw_segmentation(draw):
        n = draw(st.integers(min_points, max_points))
        k = draw(st.integers(1, min(n, max_parts or n)))
        labels = list(range(k)) + draw(st.lists(st.integers(0, k - 1), min_size=n - k, max_size=n - k))
        return Segmentation(labels=np.array(draw(st.permutations(labels))), n_parts=k)

    return draw_segmentation()


def animated_meshes(*, min_frames=1, max_frames=10, max_vertices=12, max_faces=8, max_coordinate=10.0):
    """Animated meshes: a motion (T, V, 3) of T in [min_frames, max_frames] frames and V in
    [3, max_vertices] vertices, and 1 to `max_faces` faces, all triangles or all quads (where
    V >= 4), each of distinct vertices of the mesh; not every vertex need be on a face."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _check_count("max_vertices", max_vertices, low=3)
    _check_count("max_faces", max_faces)
    _check_positive("max_coordinate", max_coordinate)

    @st.composite
    def draw_mesh(draw):
        v = draw(st.integers(3, max_vertices))
        motion = draw(motions(min_frames=min_frames, max_frames=max_frames, min_agents=v, max_agents=v, dims=3,
                              max_coordinate=max_coordinate))  # fmt: skip
        corners = draw(st.sampled_from([3, 4] if v >= 4 else [3]))
        face = st.lists(st.integers(0, v - 1), min_size=corners, max_size=corners, unique=True)
        faces = np.array(draw(st.lists(face, min_size=1, max_size=max_faces)))
        return AnimatedMesh(motion=motion, faces=faces, name=draw(st.sampled_from(["mesh", "flag", "plant"])))

    return draw_mesh()


def skinned_meshes(*, min_frames=1, max_frames=8, max_joints=5, max_vertices=16, max_influences=4,
                   max_coordinate=10.0):  # fmt: skip
    """Skinned animated meshes (``AnimatedMesh`` with a ``MeshSkin``): a skeleton of 1 to
    `max_joints` joints (a tree, or a forest, every parent before its children) posed in T in
    [min_frames, max_frames] frames (the first is the bind pose), V in [1, `max_vertices`]
    vertices each following 1 to `max_influences` joints with weights summing to 1, placed by
    linear blend skinning; rest positions and joint offsets in [-max_coordinate, max_coordinate].
    Faces (triangles of distinct vertices) where V >= 3, none otherwise."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _check_count("max_joints", max_joints)
    _check_count("max_vertices", max_vertices)
    _check_count("max_influences", max_influences)
    _check_positive("max_coordinate", max_coordinate)

    @st.composite
    def draw_skinned(draw):
        t, j = draw(st.integers(min_frames, max_frames)), draw(st.integers(1, max_joints))
        parents = [-1] + [draw(st.integers(-1, k - 1)) for k in range(1, j)]
        rest_pose = Pose(rotations=np.tile([0.0, 0, 0, 1], (j, 1)), translations=np.zeros((j, 3)))
        skeleton = Skeleton(names=[f"joint{k}" for k in range(j)], parents=parents, rest=rest_pose)
        offsets = draw(_vectors((j, 3), max_coordinate))
        rotations = draw(_unit_quaternions((t, j)))
        rotations[0] = [0.0, 0.0, 0.0, 1.0]  # frame 0 is the bind pose
        world = skeleton.world(Pose(rotations=rotations, translations=np.broadcast_to(offsets, (t, j, 3))))
        matrices = world @ np.linalg.inv(world[0])  # (T, J, 4, 4): joint world @ inverse bind
        v = draw(st.integers(1, max_vertices))
        k = draw(st.integers(1, min(max_influences, j)))
        joints = draw(hnp.arrays("int64", (v, k), elements=st.integers(0, j - 1)))
        weights = draw(hnp.arrays("float64", (v, k), elements=st.floats(0, 1)))
        weights[:, 0] += 0.5  # every vertex follows some joint
        weights /= weights.sum(axis=1, keepdims=True)
        rest = draw(_vectors((v, 3), max_coordinate))
        blended = np.einsum("vk,tvkij->tvij", weights, matrices[:, joints])
        positions = np.einsum("tvij,vj->tvi", blended[..., :3, :3], rest) + blended[..., :3, 3]
        faces = np.zeros((0, 3), dtype=np.int64)
        if v >= 3:
            face = st.lists(st.integers(0, v - 1), min_size=3, max_size=3, unique=True)
            faces = np.array(draw(st.lists(face, min_size=1, max_size=4)))
        skin = MeshSkin(joint_names=skeleton.names, parents=parents, joints=joints, weights=weights)
        return AnimatedMesh(motion=Motion(positions=positions, dt=0.1), faces=faces, skin=skin)

    return draw_skinned()


def motion_graphs(*, dims=None, max_agents=6):
    """Motion graphs over the kit's recording (``inputs.recording``, 2 to `max_agents` agents, D =
    `dims`, None: 2 or 3), with a drawn, non-empty set of its exact recurrences as transitions
    (each way, blends of 0 to 5 frames): valid graphs whose every alignment is exact."""
    _check_count("max_agents", max_agents, low=2)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_graph(draw):
        from ..graphs import MotionGraph
        from .inputs import WOBBLE_PERIOD, _alignment, recording

        d, n = draw(dims_strategy), draw(st.integers(2, max_agents))
        motion = recording(n_agents=n, seconds=8.0, dims=d, seed=draw(st.integers(0, 3)))
        lag, blend = round(WOBBLE_PERIOD / motion.dt), draw(st.integers(0, 5))
        starts = draw(st.lists(st.integers(0, motion.n_frames - lag - 6), min_size=1, max_size=6, unique=True))
        transitions = [(a, b, _alignment(motion, a, b), blend) for s in starts for a, b in ((s, s + lag), (s + lag, s))]
        return MotionGraph.assemble(motion, transitions, provenance={"builder": "flockkit.testing.strategies"})

    return draw_graph()


def walks(graph, *, max_edges=12, max_translation=10.0):
    """Walks that fit `graph` (a MotionGraph): a start node, then up to `max_edges` edges, each
    leaving the node the previous one reached, a transition only once the previous one's blend has
    played; the start pose either left out (the identity) or a proper rotation and a translation
    in [-max_translation, max_translation]."""
    from ..graphs import MotionGraph, Walk

    if not isinstance(graph, MotionGraph):
        raise InvalidArgument(f"graph must be a flockkit.MotionGraph; got {type(graph).__name__}")
    _check_count("max_edges", max_edges, low=0)
    _check_positive("max_translation", max_translation)
    leaving = {}
    for k, t in enumerate(graph.transitions):
        leaving.setdefault(t.source, []).append(k)
    d = graph.motion.dims

    @st.composite
    def draw_walk(draw):
        node = draw(st.integers(0, len(graph.nodes) - 1))
        start, edges, owed = node, [], 0  # owed: blend frames still to play before a transition
        for _ in range(draw(st.integers(0, max_edges))):
            options = [("clip", node)] if node < len(graph.clips) else []
            if owed <= 0:
                options += [("transition", k) for k in leaving.get(node, [])]
            if not options:
                break
            kind, index = draw(st.sampled_from(options))
            edges.append((kind, index))
            if kind == "clip":
                owed -= graph.clips[index].n_frames - 1
                node = graph.clips[index].target
            else:
                owed, node = graph.transitions[index].blend, graph.transitions[index].target
        if draw(st.booleans()):
            return Walk(start=start, edges=edges)
        return Walk(
            start=start, edges=edges, rotation=draw(_rotations(d)), translation=draw(_vectors((d,), max_translation))
        )

    return draw_walk()


def layered_walks(*, dims=None, max_parts=3, max_agents=4, max_edges=8):
    """(GraphLayers, LayeredWalk): 1 to `max_parts` graphs from :func:`motion_graphs` (D = `dims`,
    None: 2 or 3), each over its own points, those points dealt out over the source in a drawn
    order, and a walk per part from :func:`walks` (turns, trades of points, start poses)."""
    _check_count("max_parts", max_parts)
    _check_count("max_agents", max_agents, low=2)
    _check_count("max_edges", max_edges, low=0)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_layered(draw):
        from ..scene.layers import GraphLayers, LayeredWalk

        d = draw(dims_strategy)
        graphs = draw(st.lists(motion_graphs(dims=d, max_agents=max_agents), min_size=1, max_size=max_parts))
        graphs = [g for g in graphs if g.motion.n_frames == graphs[0].motion.n_frames]
        sizes = [g.motion.n_agents for g in graphs]
        labels = np.array(draw(st.permutations(np.repeat(np.arange(len(graphs)), sizes).tolist())))
        positions = np.empty((graphs[0].motion.n_frames, len(labels), d))
        for k, graph in enumerate(graphs):
            positions[:, labels == k] = graph.motion.positions
        source = Motion(positions=positions, dt=graphs[0].motion.dt)
        layers = GraphLayers(source=source, segmentation=Segmentation(labels=labels, n_parts=len(graphs)),
                             graphs=graphs)  # fmt: skip
        return layers, LayeredWalk(walks=[draw(walks(g, max_edges=max_edges)) for g in graphs])

    return draw_layered()


def problems(*, dims=None, max_agents=6, max_constraints=4, max_coordinate=10.0):
    """Constrained problems of 1 to `max_agents` agents over 1 to 4 s at 10 Hz, D = `dims` (None:
    2 or 3), with 1 to `max_constraints` point constraints (agents, times and positions drawn,
    velocities given, no two on one agent at one frame)."""
    _check_count("max_agents", max_agents)
    _check_count("max_constraints", max_constraints)
    _check_positive("max_coordinate", max_coordinate)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_problem(draw):
        from ..constrained import PointConstraint, Problem

        d, n = draw(dims_strategy), draw(st.integers(1, max_agents))
        frames = draw(st.integers(10, 40))
        where = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, frames)), min_size=1,
                              max_size=max_constraints, unique=True))  # fmt: skip
        constraints = [
            PointConstraint(
                agent=a, time=f / 10, position=draw(_vectors((d,), max_coordinate)), velocity=draw(_vectors((d,), 2.0))
            )  # fmt: skip
            for a, f in where
        ]
        return Problem(n_agents=n, dims=d, dt=0.1, duration=frames / 10, constraints=constraints)

    return draw_problem()


def proposals(*, motion_strategy=None):
    """Proposals as a move returns them: a motion (default: ``motions(min_frames=2)``), a frame
    window start < stop within it and a non-empty set of its agents."""
    motion_strategy = motions(min_frames=2, max_frames=12) if motion_strategy is None else motion_strategy

    @st.composite
    def draw_proposal(draw):
        from ..constrained import Proposal

        motion = draw(motion_strategy)
        start = draw(st.integers(0, motion.n_frames - 1))
        stop = draw(st.integers(start + 1, motion.n_frames))
        agents = draw(st.lists(st.integers(0, motion.n_agents - 1), min_size=1, unique=True))
        return Proposal(motion=motion, start=start, stop=stop, agents=tuple(sorted(agents)))

    return draw_proposal()


def proposal_contexts(behavior, *, dims=None, max_agents=6):
    """What a proposal move reads (ProposalContext): a drawn problem (``problems``), `behavior`
    (a behavior model stepping 0.1 s), the problem's windows, the per-frame log plausibility of its
    initial trajectories and its pinned agent-frames. Draws (context, initial trajectories)."""
    from ..interfaces import BehaviorModel

    if not isinstance(behavior, BehaviorModel):
        raise InvalidArgument(f"behavior must be a behavior model; got {type(behavior).__name__}")

    @st.composite
    def draw_context(draw):
        from ..constrained import ProposalContext, initial_trajectories, windows
        from ..constrained.sampler import pinned_frames

        problem = draw(problems(dims=dims, max_agents=max_agents))
        motion = initial_trajectories(problem, behavior, np.random.default_rng(draw(st.integers(0, 2**16))))
        context = ProposalContext(
            problem=problem,
            behavior=behavior,
            windows=tuple(windows(problem)),
            scores=np.asarray(behavior.log_plausibility(motion), dtype=np.float64),
            pinned=pinned_frames(problem),
        )
        return context, motion

    return draw_context()


# -- what optional capabilities and factory parameters hand a component -------------------------


def features(*, min_frames=1, max_frames=20, dims=None, dt=None):
    """Feature arrows (``flockkit.Features``) of T in [min_frames, max_frames] frames, D = `dims`
    (None: 2 or 3), `dt` seconds apart (None: drawn from [0.01, 1]): each arrow of length in
    [0, 1], the ends included (calm, and the strongest force), pointing any way."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    if dt is not None:
        _check_positive("dt", dt)
    dims_strategy = _dims(dims)
    dt_strategy = st.just(float(dt)) if dt is not None else st.floats(0.01, 1.0)

    @st.composite
    def draw_features(draw):
        t, d = draw(st.integers(min_frames, max_frames)), draw(dims_strategy)
        return Features(vectors=draw(_arrows(t, d)), dt=draw(dt_strategy))

    return draw_features()


def _arrows(count, d):
    """(count, d) arrows of lengths in [0, 1] (0 and 1 as often as the rest), any direction."""

    @st.composite
    def draw_arrows(draw):
        raw = draw(_vectors((count, d), 1.0))
        norms = np.linalg.norm(raw, axis=1, keepdims=True)
        directions = np.where(norms > 1e-6, raw / np.maximum(norms, 1e-6), np.eye(d)[0])
        lengths = draw(
            hnp.arrays("float64", (count, 1), elements=st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0, 1)))
        )
        return directions * lengths

    return draw_arrows()


def keyframed_arrows(*, dims=None, duration=10.0, max_keyframes=5):
    """Keyframed arrows as a walk's ``target`` takes them: a list of 1 to `max_keyframes`
    (time, vector) pairs, times increasing within [0, duration] seconds, vectors of D = `dims`
    (None: 2 or 3) coordinates and length at most 1."""
    _check_positive("duration", duration)
    _check_count("max_keyframes", max_keyframes)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_keyframes(draw):
        d = draw(dims_strategy)
        times = sorted(draw(st.lists(st.floats(0.0, duration), min_size=1, max_size=max_keyframes, unique=True)))
        vectors = draw(_arrows(len(times), d))
        return [(float(t), v) for t, v in zip(times, vectors)]

    return draw_keyframes()


def pose_times(*, min_size=1, max_size=8, max_time=10.0):
    """What a controller's ``pose(times)`` is asked: 1D arrays of `min_size` to `max_size` times
    in seconds in [0, max_time], in any order, repeats and 0 among them."""
    _check_range("min_size", min_size, "max_size", max_size, floor=0)
    _check_positive("max_time", max_time)
    elements = st.one_of(st.just(0.0), st.floats(0.0, max_time))
    return hnp.arrays("float64", st.integers(min_size, max_size), elements=elements)


def time_windows(*, max_windows=4, max_time=10.0):
    """What a controller's ``events(start, stop)`` is asked in turn: a tuple of 1 to
    `max_windows` consecutive windows (start, stop) of seconds, the first starting in
    [0, max_time], each starting where the one before stopped, some empty (start == stop)."""
    _check_count("max_windows", max_windows)
    _check_positive("max_time", max_time)

    @st.composite
    def draw_windows(draw):
        count = draw(st.integers(1, max_windows))
        cuts = sorted(draw(st.lists(st.floats(0.0, max_time), min_size=count + 1, max_size=count + 1)))
        return tuple((float(a), float(b)) for a, b in zip(cuts[:-1], cuts[1:]))

    return draw_windows()


def frame_windows(n_frames):
    """The windows ``log_plausibility`` and ``log_terms`` take for a motion of `n_frames` frames:
    (start, stop) with 0 <= start <= stop <= n_frames (empty windows too), or stop None (the
    end)."""
    _check_count("n_frames", n_frames)

    @st.composite
    def draw_window(draw):
        start = draw(st.integers(0, n_frames))
        return start, draw(st.one_of(st.none(), st.integers(start, n_frames)))

    return draw_window()


def configuration_lists(*, min_size=2, max_size=6, min_agents=1, max_agents=6, dims=None, max_coordinate=10.0):
    """What a metric's ``pairs_within`` and ``pairwise`` take: lists of `min_size` to `max_size`
    configurations of one N in [min_agents, max_agents] and one D = `dims` (None: 2 or 3),
    coordinates in [-max_coordinate, max_coordinate], copies and degenerate ones among them
    (:func:`configurations` with ``degenerate=True``)."""
    _check_range("min_size", min_size, "max_size", max_size)
    _validate(min_agents, max_agents, max_coordinate, 1.0)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_list(draw):
        n, d = draw(st.integers(min_agents, max_agents)), draw(dims_strategy)
        one = configurations(min_agents=n, max_agents=n, dims=d, max_coordinate=max_coordinate, max_speed=2.0,
                             degenerate=True)  # fmt: skip
        found = draw(st.lists(one, min_size=1, max_size=max_size))
        while len(found) < min_size or (len(found) < max_size and draw(st.booleans())):
            found.append(found[draw(st.integers(0, len(found) - 1))])  # a copy: distance 0
        return found

    return draw_list()


def index_pairs(n_items, *, max_pairs=None):
    """Pairs as ``pairwise(configurations, pairs)`` takes them: integer arrays (P, 2) of distinct
    rows (i, j), 0 <= i < j < `n_items` (>= 2), in any order, P in [1, max_pairs] (None: all)."""
    _check_count("n_items", n_items, low=2)
    if max_pairs is not None:
        _check_count("max_pairs", max_pairs)
    every = [(i, j) for i in range(n_items) for j in range(i + 1, n_items)]

    @st.composite
    def draw_pairs(draw):
        chosen = draw(st.lists(st.sampled_from(every), min_size=1, max_size=max_pairs or len(every), unique=True))
        return np.array(chosen, dtype=np.int64).reshape(-1, 2)

    return draw_pairs()


def guides(*, n_agents, steps, dims, max_guided=None, max_coordinate=10.0):
    """What a behavior declaring ``Capabilities(guide=True)`` takes as ``guide``: a mapping of 1
    to `max_guided` (None: all) of `n_agents` agents to (steps + 1, `dims`) paths, coordinates in
    [-max_coordinate, max_coordinate]."""
    _check_count("n_agents", n_agents)
    _check_count("steps", steps, low=0)
    _dims(dims)
    if dims is None:
        raise InvalidArgument("dims must be 2 or 3: a guide is for a flock of known dimension")
    if max_guided is not None:
        _check_count("max_guided", max_guided)
    _check_positive("max_coordinate", max_coordinate)

    @st.composite
    def draw_guide(draw):
        agents = draw(st.lists(st.integers(0, n_agents - 1), min_size=1, max_size=max_guided or n_agents, unique=True))
        return {a: draw(_vectors((steps + 1, dims), max_coordinate)) for a in sorted(agents)}

    return draw_guide()


def group_guides(*, n_agents, steps, dims, max_groups=3, max_coordinate=10.0):
    """What a behavior declaring ``Capabilities(group_guide=True)`` takes as ``group_guide``: a
    list of 1 to `max_groups` (agents, path) pairs, agents a sorted tuple of distinct indices of
    `n_agents` (no agent in two groups), path the (steps + 1, `dims`) positions its centre of mass
    should follow, coordinates in [-max_coordinate, max_coordinate]."""
    _check_count("n_agents", n_agents)
    _check_count("steps", steps, low=0)
    _dims(dims)
    if dims is None:
        raise InvalidArgument("dims must be 2 or 3: a group guide is for a flock of known dimension")
    _check_count("max_groups", max_groups)
    _check_positive("max_coordinate", max_coordinate)

    @st.composite
    def draw_groups(draw):
        order = draw(st.permutations(range(n_agents)))
        count = draw(st.integers(1, min(max_groups, n_agents)))
        cuts = sorted(draw(st.lists(st.integers(1, n_agents), min_size=count, max_size=count, unique=True)))
        starts = [0, *cuts[:-1]]
        return [
            (tuple(sorted(order[a:b])), draw(_vectors((steps + 1, dims), max_coordinate))) for a, b in zip(starts, cuts)
        ]

    return draw_groups()


def regions(*, dims=None, kinds=("ball", "box", "polygon"), max_coordinate=10.0, max_size=5.0):
    """Regions (``flockkit.regions``) as obstacles, walk regions and constraint shapes: balls
    (discs, spheres), axis-aligned boxes and, in 2D, simple polygons of 3 to 8 vertices, convex
    or not (in order of angle about their centre, no gap of half a turn, so never self-crossing
    and the centre inside); D = `dims` (None: 2 or 3), centres in [-max_coordinate,
    max_coordinate], radii and half-sides in [max_size / 100, max_size]."""
    from ..regions import Ball, Box, Polygon

    _dims(dims)
    kinds = tuple(kinds) if not isinstance(kinds, str) else (kinds,)
    if not kinds or any(k not in ("ball", "box", "polygon") for k in kinds):
        raise InvalidArgument(f"kinds must be a non-empty subset of ('ball', 'box', 'polygon'); got {kinds!r}")
    if dims == 3:  # polygons are 2D
        kinds = tuple(k for k in kinds if k != "polygon")
        if not kinds:
            raise InvalidArgument("polygons are 2D; kinds=('polygon',) needs dims=2 or None")
    _check_positive("max_coordinate", max_coordinate)
    _check_positive("max_size", max_size)
    sizes = st.floats(max_size / 100, max_size)

    @st.composite
    def draw_region(draw):
        kind = draw(st.sampled_from(kinds))
        d = 2 if kind == "polygon" else draw(_dims(dims))
        centre = draw(_vectors((d,), max_coordinate))
        if kind == "ball":
            return Ball(center=centre, radius=draw(sizes))
        if kind == "box":
            half = draw(hnp.arrays("float64", (d,), elements=sizes))
            return Box(lower=centre - half, upper=centre + half)
        k = draw(st.integers(3, 8))
        jitter = draw(hnp.arrays("float64", (k,), elements=st.floats(-0.24, 0.24)))  # gaps under half a turn
        angle = (np.arange(k) + jitter) * 2 * math.pi / k
        radius = draw(hnp.arrays("float64", (k,), elements=sizes))
        return Polygon(vertices=centre + radius[:, None] * np.column_stack([np.cos(angle), np.sin(angle)]))

    return draw_region()


def declared_capabilities(*, kind):
    """Capabilities (``flockkit.Capabilities``) a component of `kind` (a name in
    ``flockkit.kinds.KINDS``) may declare: a non-empty set of dimensions, and any of the fields
    that kind reads, ``coupling`` only with ``residuals``."""
    from ..interfaces import Capabilities
    from ..kinds import KINDS

    if kind not in KINDS:
        raise InvalidArgument(f"kind must be one of {sorted(KINDS)}; got {kind!r}")
    fields = sorted(KINDS[kind].fields)

    @st.composite
    def draw_capabilities(draw):
        declared = {"dims": draw(st.sampled_from([(2,), (3,), (2, 3)]))}
        for field in fields:
            if field == "plausibility_reach":
                declared[field] = draw(st.one_of(st.none(), st.integers(0, 5)))
            else:
                declared[field] = draw(st.booleans())
        if declared.get("coupling"):
            declared["residuals"] = True
        return Capabilities(**declared)

    return draw_capabilities()
