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

from ..constrained.problem import ComConstraint
from ..mesh import AnimatedMesh
from ..motion import Alignment, Configuration, Motion, State
from ..scene.segmentation import Segmentation
from ..skeleton import Event, Pose, SkeletalClip, Skeleton

__all__ = [
    "configurations",
    "symmetric_configurations",
    "states",
    "motions",
    "alignments",
    "com_tracks",
    "problems",
    "proposals",
    "proposal_contexts",
    "motion_graphs",
    "walks",
    "segmentations",
    "poses",
    "skeletons",
    "events",
    "skeletal_clips",
    "animated_meshes",
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


def configurations(*, min_agents=1, max_agents=10, dims=None, max_coordinate=100.0, max_speed=10.0):
    """Configurations with N in [min_agents, max_agents], D = `dims` (None: 2 or 3), coordinates
    in [-max_coordinate, max_coordinate] and velocity components in [-max_speed, max_speed]."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_configuration(draw):
        shape = (draw(st.integers(min_agents, max_agents)), draw(dims_strategy))
        return Configuration(
            positions=draw(_vectors(shape, max_coordinate)), velocities=draw(_vectors(shape, max_speed))
        )

    return draw_configuration()


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


def _rotations(dims):
    """Proper rotations (D, D), uniformly spread (QR of a Gaussian matrix, signs fixed)."""

    @st.composite
    def draw_rotation(draw):
        matrix = draw(hnp.arrays("float64", (dims, dims), elements=st.floats(-1, 1).filter(lambda x: abs(x) > 1e-3)))
        q, r = np.linalg.qr(matrix + 3 * np.eye(dims))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] *= -1
        return q

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


def symmetric_configurations(*, dims=None, max_agents=16, max_coordinate=10.0):
    """Configurations with ties and symmetries, placed and turned at random: regular polygons,
    square (cubic) grids, agents on one spot, pairs of coincident agents, one agent, evenly
    spaced agents on a line; at rest, all heading one way, or turning about their centre. N at
    most `max_agents` (>= 4), D = `dims` (None: 2 or 3), centres within `max_coordinate`."""
    _check_count("max_agents", max_agents, low=4)
    _check_positive("max_coordinate", max_coordinate)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_degenerate(draw):
        d = draw(dims_strategy)
        shape = draw(st.sampled_from(["polygon", "grid", "spot", "pairs", "one", "line"]))
        if shape == "polygon":
            n = draw(st.integers(3, max_agents))
            angle = np.arange(n) * 2 * math.pi / n
            flat = np.column_stack([np.cos(angle), np.sin(angle)])
            points = np.column_stack([flat, np.zeros((n, d - 2))])
        elif shape == "grid":
            side = draw(st.integers(2, max(2, int(max_agents ** (1 / d)))))
            points = np.stack(np.meshgrid(*[np.arange(float(side))] * d, indexing="ij"), axis=-1).reshape(-1, d)
        elif shape == "spot":
            points = np.zeros((draw(st.integers(2, max_agents)), d))
        elif shape == "pairs":
            points = np.repeat(draw(_vectors((draw(st.integers(2, max_agents // 2)), d), 1.0)), 2, axis=0)
        elif shape == "one":
            points = np.zeros((1, d))
        else:
            points = np.outer(np.arange(float(draw(st.integers(2, max_agents)))), np.eye(d)[0])
        scale = draw(st.floats(0.1, 2.0))
        rotation = draw(_rotations(d))
        centered = (points - points.mean(axis=0)) * scale
        motion = draw(st.sampled_from(["rest", "heading", "turning"]))
        if motion == "rest":
            velocities = np.zeros_like(centered)
        elif motion == "heading":
            velocities = np.tile(np.eye(d)[0], (len(centered), 1))
        else:
            velocities = np.zeros_like(centered)
            velocities[:, 0], velocities[:, 1] = -centered[:, 1], centered[:, 0]
        shift = draw(_vectors((d,), max_coordinate))
        return Configuration(positions=centered @ rotation.T + shift, velocities=velocities @ rotation.T)

    return draw_degenerate()


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


def skeletal_clips(*, min_joints=1, max_joints=6, min_frames=2, max_frames=30, fps=30.0):
    """Skeletal clips over a drawn skeleton: T in [min_frames, max_frames] frames at `fps`, unit
    rotations per frame and joint, root translations, and events within the clip's duration."""
    _check_range("min_joints", min_joints, "max_joints", max_joints)
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _check_positive("fps", fps)

    @st.composite
    def draw_clip(draw):
        skeleton = draw(skeletons(min_joints=min_joints, max_joints=max_joints))
        t = draw(st.integers(min_frames, max_frames))
        duration = (t - 1) / fps
        return SkeletalClip(
            skeleton=skeleton,
            fps=float(fps),
            rotations=draw(_unit_quaternions((t, skeleton.n_joints))),
            translations=draw(_vectors((t, 3), 10.0)),
            events=draw(st.lists(events(max_time=max(duration, 1e-9)), max_size=3)) if duration > 0 else [],
            name=draw(st.sampled_from(["walk", "idle", "run"])),
        )

    return draw_clip()


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


def animated_meshes(*, min_frames=1, max_frames=10, max_vertices=12, max_coordinate=10.0):
    """Animated meshes: a motion (T, V, 3) of V in [3, max_vertices] vertices and triangles
    indexing them (a fan over the vertices)."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _check_count("max_vertices", max_vertices, low=3)

    @st.composite
    def draw_mesh(draw):
        v = draw(st.integers(3, max_vertices))
        motion = draw(motions(min_frames=min_frames, max_frames=max_frames, min_agents=v, max_agents=v, dims=3,
                              max_coordinate=max_coordinate))  # fmt: skip
        faces = np.array([[0, k, k + 1] for k in range(1, v - 1)])
        return AnimatedMesh(motion=motion, faces=faces, name="mesh")

    return draw_mesh()


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


def walks(graph, *, max_edges=12):
    """Walks that fit `graph` (a MotionGraph): a start node, then up to `max_edges` edges, each
    leaving the node the previous one reached, a transition only once the previous one's blend has
    played."""
    from ..graphs import MotionGraph, Walk

    if not isinstance(graph, MotionGraph):
        raise InvalidArgument(f"graph must be a flockkit.MotionGraph; got {type(graph).__name__}")
    _check_count("max_edges", max_edges, low=0)
    leaving = {}
    for k, t in enumerate(graph.transitions):
        leaving.setdefault(t.source, []).append(k)

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
        return Walk(start=start, edges=edges)

    return draw_walk()


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
