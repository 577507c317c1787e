"""Motion graphs (paper 000 section 4.3, after Kovar et al.): clips of a source motion joined by
transitions between similar configurations.

A builder chooses transitions, pairs of source frames (leave at `start`, arrive at `end`) with the
metric's Alignment; :meth:`MotionGraph.assemble` turns them into a graph: every transition frame
is a node, consecutive nodes are joined by clips (frame ranges of the source), and dead ends are
trimmed by keeping the largest strongly connected component.

A source that loops (a walk, run or flapping cycle whose first frame follows its last: see
:func:`loop_period`) gives a *looping* graph (``MotionGraph.period``): its last node's clip plays
on across the loop to its first node, so a walk goes round the cycle without a transition, and
blends run across the loop too. On a short cycle, time shifts (:func:`phase_shifts`: transitions
to a frame a few frames on or back, the same motion sooner or later, hidden by their blend) let
walks start at any phase and drift out of step with each other.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from types import MappingProxyType

import attrs
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .. import _npzfile, rigid
from .._arrays import check_finite, readonly_int
from ..errors import FileFormatError, ValidationError
from ..motion import DEFAULT_UP, Alignment, Motion, _check_rotation, heading_axes
from ..validate import integer

__all__ = [
    "MotionGraph",
    "Clip",
    "Transition",
    "Walk",
    "turns",
    "loop_period",
    "phase_shifts",
    "local_minima",
    "local_minima_of_cells",
]

# Files of graphs that loop are version 2 (they hold the period, which version 1 readers would
# ignore and then misread the clips); other graphs are still written as version 1.
GRAPH_FORMAT_VERSION = 2
PLAIN_GRAPH_FORMAT_VERSION = 1


@attrs.frozen(kw_only=True)
class Clip:
    """An edge that plays source frames ``start..stop`` (both included) from node `source` to `target`.

    Attributes
    ----------
    source, target : int
        The nodes it joins: clip k of a MotionGraph joins node k to node k + 1. On a looping graph
        the last clip joins the last node to node 0.
    start, stop : int
        The source frames of those nodes (``graph.nodes[k]``, ``graph.nodes[k + 1]``), start < stop.
        The last clip of a looping graph plays on across the loop: its stop is
        ``graph.nodes[0] + graph.period``, and frame f of it is source frame ``f % period``.
    """

    source: int
    target: int
    start: int
    stop: int

    @property
    def n_frames(self) -> int:
        """The source frames it spans, both ends included: ``stop - start + 1``."""
        return self.stop - self.start + 1


@attrs.frozen(kw_only=True, eq=False)
class Transition:
    """An edge from node `source` (source frame `start`) to node `target` (source frame `end`).

    `alignment` is ``metric.compare(configuration(start), configuration(end))``: it lays the
    motion continuing from `end` onto the world of `start`, and agent i of `start` continues as
    agent ``alignment.assignment[i]`` of `end`. `blend` is the number of frames over which
    synthesis blends the two motions.

    A transition from a frame to itself (`start` == `end`) is a *turn*: the same motion, rotated
    about the group's center of mass, so that over the blend the group steers onto a new
    heading. Builders add turns so that walks can steer a group that the recording barely turns.

    Attributes
    ----------
    source, target : int
        The nodes it joins (indices into ``graph.nodes``).
    start, end : int
        Their source frames: ``graph.nodes[source]`` and ``graph.nodes[target]``.
    alignment : Alignment
        As above; its rotation and translation are proper and finite, its assignment a permutation.
    blend : int
        Frames of blending after it, >= 0; a walk takes no other transition until they have played.
    """

    source: int
    target: int
    start: int
    end: int
    alignment: Alignment
    blend: int

    def __eq__(self, other):
        if not isinstance(other, Transition):
            return NotImplemented
        return attrs.astuple(self, recurse=False) == attrs.astuple(other, recurse=False)

    __hash__ = None

    @property
    def is_turn(self) -> bool:
        """Whether it leads from a frame to itself (a turn, see above)."""
        return self.start == self.end


def _sequence(value, field: str) -> list:
    try:
        if isinstance(value, str | bytes):
            raise TypeError
        return list(value)
    except TypeError:
        raise ValidationError(f"{field} must be a sequence; got {type(value).__name__}") from None


def _float_array(value, field: str) -> np.ndarray:
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError(f"{field} must be an array of numbers; got {type(value).__name__}") from None


def _start_rotation(value) -> np.ndarray | None:
    """A walk's start rotation: None, or a proper (D, D) rotation (a reflection or a scaling would
    mirror or resize the source), read-only."""
    if value is None:
        return None
    rotation = _float_array(value, "Walk.rotation")
    _check_rotation(rotation, "Walk.rotation")
    rotation.flags.writeable = False
    return rotation


def _start_translation(value) -> np.ndarray | None:
    if value is None:
        return None
    translation = _float_array(value, "Walk.translation")
    if translation.shape not in ((2,), (3,)):
        raise ValidationError(f"Walk.translation must have shape (D,) with D in {{2, 3}}; got {translation.shape}")
    check_finite(translation, field="Walk.translation")
    translation.flags.writeable = False
    return translation


def _edge(value) -> tuple[str, int]:
    kind, index = value if isinstance(value, (tuple, list)) and len(value) == 2 else (None, None)
    if (
        not isinstance(kind, str)  # an array would compare elementwise
        or kind not in ("clip", "transition")
        or isinstance(index, bool)
        or not isinstance(index, (int, np.integer))
        or index < 0
    ):
        raise ValidationError(f"Walk.edges entries must be ('clip' or 'transition', index >= 0); got {value!r}")
    return kind, int(index)


_EDGE_KINDS = {"clip": False, "transition": True}


def _edges(value) -> tuple:
    """Walk.edges as a tuple of (kind, int index) pairs. A walk strategy hands over thousands of
    edges: they are checked all at once (every entry a pair whose kind is one of the two names
    and whose index is a non-negative integer, not a bool), and one by one by :func:`_edge` only
    to name the first bad one."""
    edges = _sequence(value, "Walk.edges")
    if not edges:
        return ()
    if set(map(type, edges)) <= {tuple, list} and set(map(len, edges)) == {2}:
        kinds, indices = zip(*edges)
        types = set(map(type, indices))
        if set(kinds) <= _EDGE_KINDS.keys() and set(map(type, kinds)) == {str}:
            if types == {int} and min(indices) >= 0:  # pairs as they should be: kept, not made again
                return tuple(edges) if set(map(type, edges)) == {tuple} else tuple(zip(kinds, indices))
            if all(issubclass(t, int | np.integer) and not issubclass(t, bool | np.bool_) for t in types):
                indices = [int(i) for i in indices]
                if min(indices) >= 0:
                    return tuple(zip(kinds, indices))
    return tuple(_edge(e) for e in edges)


@attrs.frozen(kw_only=True, eq=False)
class Walk:
    """A path through a MotionGraph: where it starts, how the source is placed, and its edges.

    Its length is that of the motion it plays, ``flockkit.synthesize(graph, walk)``: the start
    node's frame, then for each ``("clip", k)`` the clip's frames after its first
    (``clip.n_frames - 1``); a transition plays no frame of its own (the next clip carries on from
    its target, blended over ``transition.blend`` frames). Its duration in seconds is (frames
    played - 1) x the source's dt: a walk strategy asked for `duration` returns a walk at least
    that long.

    Made with keywords, as ``Walk(start=0, edges=[("clip", 0), ("transition", 2)])``; every
    field is checked when it is made.

    Attributes
    ----------
    start : int
        The node the walk starts at.
    edges : tuple of (str, int)
        ``("clip", k)`` (``graph.clips[k]``) or ``("transition", k)`` (``graph.transitions[k]``),
        each leaving the node the previous one reached; a transition only once the previous
        one's blend has played.
    rotation, translation : ndarray or None
        The start pose: source coordinates map to the world as ``rotation @ p + translation``
        (a proper (D, D) rotation and a (D,) vector; either None: no rotation, no translation).
    """

    start: int = attrs.field(converter=lambda v: integer(v, "Walk.start", minimum=0))
    edges: tuple = attrs.field(converter=_edges)
    rotation: np.ndarray = attrs.field(default=None, converter=lambda v: _start_rotation(v))
    translation: np.ndarray = attrs.field(default=None, converter=lambda v: _start_translation(v))
    _is_transition: np.ndarray = attrs.field(init=False, repr=False, eq=False)
    _index: np.ndarray = attrs.field(init=False, repr=False, eq=False)

    def __attrs_post_init__(self):
        if self.start < 0:
            raise ValidationError(f"Walk.start must be a node index >= 0; got {self.start}")
        if self.rotation is not None and self.translation is not None and len(self.translation) != len(self.rotation):
            raise ValidationError(
                f"Walk.translation must have one entry per dimension of Walk.rotation ({len(self.rotation)}); "
                f"got {len(self.translation)}"
            )
        kinds, indices = zip(*self.edges) if self.edges else ((), ())
        object.__setattr__(self, "_is_transition", np.array([_EDGE_KINDS[kind] for kind in kinds], dtype=bool))
        object.__setattr__(self, "_index", np.fromiter(indices, dtype=np.int64, count=len(indices)))

    @property
    def edge_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(is_transition, index) per edge, as arrays."""
        return self._is_transition, self._index

    def pose(self, dims: int) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, translation) of the start pose, identity where not given."""
        rotation = np.eye(dims) if self.rotation is None else np.asarray(self.rotation, dtype=np.float64)
        translation = np.zeros(dims) if self.translation is None else np.asarray(self.translation, dtype=np.float64)
        if rotation.shape != (dims, dims) or translation.shape != (dims,):
            raise ValidationError(f"Walk start pose must be a ({dims}, {dims}) rotation and a ({dims},) translation")
        return rotation, translation

    def __eq__(self, other):
        if not isinstance(other, Walk):
            return NotImplemented
        same_pose = all(
            (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
            for x, y in ((self.rotation, other.rotation), (self.translation, other.translation))
        )
        return self.start == other.start and self.edges == other.edges and same_pose

    __hash__ = None


def _frozen_json(value, field: str) -> Mapping:
    try:
        return MappingProxyType(json.loads(json.dumps(dict(value or {}))))
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{field} must be a JSON-serializable mapping: {exc}") from None


def _thaw(value):
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_thaw(v) for v in value]
    return value


@attrs.frozen(kw_only=True, eq=False)
class EdgeTables:
    """A MotionGraph's edges as arrays: clip k and transition k by index."""

    clip_start: np.ndarray
    clip_stop: np.ndarray
    transition_source: np.ndarray
    transition_target: np.ndarray
    transition_start: np.ndarray
    transition_blend: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    assignment: np.ndarray
    clip_target: np.ndarray
    shift: np.ndarray
    out: tuple  # per node, the transitions leaving it, in order

    def leaving(self, node: int) -> tuple:
        """The transitions leaving `node`, in order."""
        return self.out[node] if 0 <= node < len(self.out) else ()

    @classmethod
    def of(cls, graph) -> EdgeTables:
        t = graph.transitions
        out = [[] for _ in graph.nodes]
        for index, x in enumerate(t):
            if 0 <= x.source < len(out):
                out[x.source].append(index)
        return cls(
            out=tuple(tuple(o) for o in out),
            clip_start=np.array([c.start for c in graph.clips], dtype=np.int64),
            clip_stop=np.array([c.stop for c in graph.clips], dtype=np.int64),
            clip_target=np.array([c.target for c in graph.clips], dtype=np.int64),
            shift=_shifts(graph),
            transition_source=np.array([x.source for x in t], dtype=np.int64),
            transition_target=np.array([x.target for x in t], dtype=np.int64),
            transition_start=np.array([x.start for x in t], dtype=np.int64),
            transition_blend=np.array([x.blend for x in t], dtype=np.int64),
            rotation=np.array([x.alignment.rotation for x in t]),
            translation=np.array([x.alignment.translation for x in t]),
            assignment=np.array([x.alignment.assignment for x in t]),
        )


@attrs.frozen(kw_only=True, eq=False)
class MotionGraph:
    """A motion graph over a source Motion.

    Attributes
    ----------
    motion : Motion
        The source recording.
    nodes : ndarray of int, shape (K,)
        Source frame of each node, increasing.
    clips : tuple of Clip
        Clip k joins node k to node k + 1 (on a looping graph, clip K - 1 joins node K - 1 to
        node 0, across the loop).
    transitions : tuple of Transition
    params : mapping
        The builder's parameters, as JSON values (threshold chosen, candidate stride, ...).
    provenance : mapping
        Metric, builder, flockkit version and seed, as JSON values.
    period : int, optional
        For a source that loops, the frames of one cycle: source frame ``period + f`` is frame f
        (``period`` is the number of frames, or one less where the last frame repeats the first).
        Nodes lie within the first `period` frames, the last clip plays across the loop and
        blends may run past the last frame, on from the first. None: the source does not loop.
    """

    motion: Motion
    nodes: np.ndarray = attrs.field(converter=lambda v: readonly_int(v, field="MotionGraph.nodes"))
    clips: tuple = attrs.field(converter=tuple)
    transitions: tuple = attrs.field(converter=tuple)
    params: Mapping = attrs.field(factory=dict, converter=lambda v: _frozen_json(v, "MotionGraph.params"))
    provenance: Mapping = attrs.field(factory=dict, converter=lambda v: _frozen_json(v, "MotionGraph.provenance"))
    period: int | None = attrs.field(default=None, converter=lambda v: _period(v))
    _tables: EdgeTables = attrs.field(init=False, repr=False, eq=False)

    def __attrs_post_init__(self):
        self._validate()
        object.__setattr__(self, "_tables", EdgeTables.of(self))

    @property
    def tables(self) -> EdgeTables:
        """The edges as arrays, for vectorized walking and playback."""
        return self._tables

    @property
    def loops(self) -> bool:
        """Whether the source loops (``period`` is set): walks go round it along clips."""
        return self.period is not None

    @property
    def shifts(self) -> np.ndarray:
        """Per transition, the frames by which it shifts time if it is a *phase shift*, else 0.

        A phase shift leads to a frame at most (blend + 1) / 3 frames on (> 0) or back (< 0),
        counted around the loop on a looping graph, with no rotation, translation or exchange of
        points: it plays the same motion a little sooner or later, and its smoothstep blend
        (whose steepest step is 1.5 / (blend + 1) of the jump) hides the jump within half a
        frame's step. Walks take them to drift in time (paper 002's asynchronous duplicates)."""
        return self._tables.shift

    def _validate(self):
        k, frames = len(self.nodes), self.motion.n_frames
        if self.period is not None and self.period > frames:
            raise ValidationError(f"MotionGraph.period must be at most the source's {frames} frames; got {self.period}")
        last = frames if self.period is None else self.period
        if (
            k < 1
            or self.nodes.ndim != 1
            or np.any(np.diff(self.nodes) <= 0)
            or self.nodes[0] < 0
            or self.nodes[-1] >= last
        ):
            raise ValidationError(
                f"MotionGraph.nodes must be increasing source frames in 0..{last - 1}; got {self.nodes}"
            )
        expected = _clips(self.nodes, self.period)
        for index, clip in enumerate(self.clips):
            if index < len(expected) and clip != expected[index]:
                e = expected[index]
                raise ValidationError(
                    f"MotionGraph.clips[{index}] must join node {e.source} to node {e.target} by their frames "
                    f"({e.start}..{e.stop})"
                )
        if len(self.clips) != len(expected):
            raise ValidationError(
                f"MotionGraph needs {len(expected)} clips for {k} nodes{' (looping)' if self.loops else ''}; got "
                f"{len(self.clips)}"
            )
        if not self.transitions:
            raise ValidationError("a MotionGraph needs at least one transition; without one there is nothing to walk")
        n, d = self.motion.n_agents, self.motion.dims
        for index, transition in enumerate(self.transitions):
            field = f"MotionGraph.transitions[{index}]"
            if not (0 <= transition.source < k and 0 <= transition.target < k):
                raise ValidationError(f"{field} joins nodes outside 0..{k - 1}")
            if (transition.start, transition.end) != (self.nodes[transition.source], self.nodes[transition.target]):
                raise ValidationError(f"{field} frames do not match its nodes")
            if transition.alignment.assignment.shape != (n,) or transition.alignment.rotation.shape != (d, d):
                raise ValidationError(f"{field}.alignment is not for {n} agents in {d}D")
            if not 0 <= transition.blend < frames:
                raise ValidationError(f"{field}.blend must be a frame count in 0..{frames - 1}; got {transition.blend}")
            if self.period is None and transition.start + transition.blend > frames - 1:
                raise ValidationError(
                    f"{field} leaves frame {transition.start} with a blend of {transition.blend} frames, past the "
                    f"recording's last frame {frames - 1}: the motion it blends away from must go on that long"
                )

    # -- building ---------------------------------------------------------------------------

    @classmethod
    def assemble(
        cls,
        motion: Motion,
        transitions: Sequence[tuple[int, int, Alignment, int]],
        *,
        params: Mapping | None = None,
        provenance: Mapping | None = None,
        period: int | None = None,
    ) -> MotionGraph:
        """Build a graph from transitions ``(start_frame, end_frame, alignment, blend)``: nodes at
        every transition frame, clips between consecutive nodes, trimmed to the largest strongly
        connected component (ties: the one holding the earliest frame). Transitions that land less
        than the longest blend before the last kept frame, or leave less than their blend before the
        recording's end (the motion they blend away from runs out), are dropped (and the trimming
        repeated), so a walk can always continue and be played.

        With `period` (a looping source, see :func:`loop_period`) nothing is trimmed: the clips go
        round the loop, so every node reaches every other, and blends run on across it; the
        transitions' frames must lie within the first `period` frames.

        Raises ValidationError if no transitions are given (a graph needs at least one loop).
        """
        if not transitions:
            raise ValidationError(
                "no transitions: the recording has no pair of similar configurations under the builder's "
                "threshold; raise the threshold or record longer motion"
            )
        transitions = list(transitions)
        if period is not None:
            period = _period(period)
            outside = [(int(s), int(e)) for s, e, _, _ in transitions if not (0 <= s < period and 0 <= e < period)]
            if outside:
                raise ValidationError(
                    f"MotionGraph.assemble: transition {outside[0]} leaves or lands outside the loop's frames "
                    f"0..{period - 1}"
                )
            nodes = np.unique([int(f) for s, e, _, _ in transitions for f in (s, e)])
            renumber = {int(f): i for i, f in enumerate(nodes)}
            looping = [
                Transition(source=renumber[int(s)], target=renumber[int(e)], start=int(s), end=int(e), alignment=a,
                           blend=int(b))
                for s, e, a, b in transitions
            ]  # fmt: skip
            return cls(motion=motion, nodes=nodes, clips=_clips(nodes, period), transitions=looping, params=params,
                       provenance=provenance, period=period)  # fmt: skip
        while True:
            nodes = _strongly_connected_frames(transitions)
            last = nodes[-1] if len(nodes) else -1
            kept = {int(f) for f in nodes}
            # A transition must land at least the longest blend before the last frame, so that a
            # walk can always go on: clips are always allowed, and at the last node every blend is done.
            longest = max(t[3] for t in transitions)
            lands = [t for t in transitions if t[0] in kept and t[1] in kept and t[1] + longest <= last]
            usable = [t for t in lands if t[0] + t[3] < motion.n_frames]
            if len(usable) == len(transitions):
                break
            transitions = usable
            if not transitions:
                raise ValidationError("the transitions form no loop through the recording; nothing can be walked")
        renumber = {int(f): i for i, f in enumerate(nodes)}
        kept_transitions = [
            Transition(source=renumber[s], target=renumber[e], start=int(s), end=int(e), alignment=a, blend=int(b))
            for s, e, a, b in transitions
        ]
        return cls(
            motion=motion,
            nodes=nodes,
            clips=_clips(nodes),
            transitions=kept_transitions,
            params=params,
            provenance=provenance,
        )

    # -- queries ----------------------------------------------------------------------------

    def out_edges(self, node: int) -> list[tuple[str, int]]:
        """Edges leaving `node`: ``("clip", k)`` and ``("transition", k)`` pairs, clips first."""
        edges = [("clip", node)] if node < len(self.clips) else []
        return edges + [("transition", i) for i in self._tables.leaving(node)]

    def edge_target(self, edge: tuple[str, int]) -> int:
        """The node a walk reaches by taking `edge` (``("clip", k)`` or ``("transition", k)``)."""
        kind, index = edge
        return (self.clips if kind == "clip" else self.transitions)[index].target

    def allowed_edges(self, node: int, frames_since_transition: int) -> list[tuple[str, int]]:
        """Edges a walk may take at `node`: a transition only once `frames_since_transition`
        frames of clips since the last one cover the longest blend of the graph, so that the last
        one's blend has played out whichever it was, and blends never overlap. At a walk's start
        no transition has been taken: pass ``math.inf`` (any transition may be taken); after a
        transition, 0; after a clip, add the clip's frames after its first."""
        longest = int(self.tables.transition_blend.max())
        return [edge for edge in self.out_edges(node) if edge[0] == "clip" or frames_since_transition >= longest]

    def kept_frames(self) -> int:
        """Source frames that some clip plays."""
        if self.period is not None:
            return self.period
        return int(self.nodes[-1] - self.nodes[0] + 1) if len(self.clips) else 1

    def stats(self) -> dict:
        """Plain numbers describing the graph; equal graphs give equal dicts."""
        distances = np.array(
            [t.alignment.distance for t, shift in zip(self.transitions, self.shifts) if not t.is_turn and not shift]
        )
        lengths = np.array([c.n_frames - 1 for c in self.clips], dtype=float)
        summary = (
            {"min": float(distances.min()), "median": float(np.median(distances)), "max": float(distances.max())}
            if len(distances)
            else {"min": None, "median": None, "max": None}
        )
        return {
            "nodes": int(len(self.nodes)),
            "edges": len(self.clips) + len(self.transitions),
            "clips": len(self.clips),
            "transitions": len(self.transitions),
            "turns": sum(t.is_turn for t in self.transitions),
            "phase_shifts": int(np.count_nonzero(self.shifts)),
            "period": self.period,
            "source_frames": self.motion.n_frames,
            "frames_kept": self.kept_frames(),
            "fraction_kept": self.kept_frames() / self.motion.n_frames,
            "mean_clip_seconds": float(lengths.mean() * self.motion.dt) if len(lengths) else 0.0,
            "transition_cost": summary,
        }

    def to_networkx(self):
        """A ``networkx.MultiDiGraph``: nodes carry `frame`; edges carry `kind`, `index` and, for
        transitions, `distance` and `blend`. Needs networkx."""
        try:
            import networkx as nx
        except ImportError:
            from .errors import MissingDependencyError

            raise MissingDependencyError("MotionGraph.to_networkx needs networkx: pip install networkx") from None
        graph = nx.MultiDiGraph()
        for node, frame in enumerate(self.nodes):
            graph.add_node(node, frame=int(frame))
        for index, clip in enumerate(self.clips):
            graph.add_edge(clip.source, clip.target, kind="clip", index=index, frames=clip.n_frames)
        for index, t in enumerate(self.transitions):
            graph.add_edge(
                t.source, t.target, kind="transition", index=index, distance=t.alignment.distance, blend=t.blend
            )
        return graph

    def __eq__(self, other):
        if not isinstance(other, MotionGraph):
            return NotImplemented
        return (
            self.motion == other.motion
            and np.array_equal(self.nodes, other.nodes)
            and self.clips == other.clips
            and self.transitions == other.transitions
            and _thaw(self.params) == _thaw(other.params)
            and _thaw(self.provenance) == _thaw(other.provenance)
            and self.period == other.period
        )

    __hash__ = None

    # -- files -----------------------------------------------------------------------------

    def _to_arrays(self) -> dict[str, np.ndarray]:
        """The graph's own arrays (its motion's are written separately)."""
        tables = self.tables
        looping = {} if self.period is None else {"period": np.array(self.period, dtype=np.int64)}
        return {
            **looping,
            "nodes": self.nodes,
            "transition_nodes": np.stack([tables.transition_source, tables.transition_target], axis=1).reshape(-1, 2),
            "transition_blend": tables.transition_blend,
            "transition_distance": np.array([t.alignment.distance for t in self.transitions]),
            "transition_assignment": tables.assignment,
            "transition_rotation": tables.rotation,
            "transition_translation": tables.translation,
        }

    @classmethod
    def _from_arrays(cls, arrays, motion: Motion, params, provenance, source) -> MotionGraph:
        """The inverse of :meth:`_to_arrays` over `motion`; FileFormatError naming `source`."""
        names = ("transition_nodes", "transition_blend", "transition_distance", "transition_assignment",
                 "transition_rotation", "transition_translation")  # fmt: skip
        lengths = {name: len(arrays[name]) if name in arrays and arrays[name].ndim else None for name in names}
        if len(set(lengths.values())) != 1:
            raise FileFormatError(f"{source}: invalid motion graph: its transition arrays differ in length: {lengths}")
        try:
            nodes = arrays["nodes"]
            period = int(arrays["period"]) if "period" in arrays else None
            transitions = [
                Transition(
                    source=int(s),
                    target=int(e),
                    start=int(nodes[s]),
                    end=int(nodes[e]),
                    blend=int(blend),
                    alignment=Alignment(distance=dist, assignment=assign, rotation=rot, translation=shift),
                )
                for (s, e), blend, dist, assign, rot, shift in zip(*(arrays[name] for name in names))
            ]
            return cls(motion=motion, nodes=nodes, clips=_clips(nodes, period), transitions=transitions, params=params,
                       provenance=provenance, period=period)  # fmt: skip
        except (KeyError, IndexError, TypeError, ValueError, OverflowError) as exc:
            raise FileFormatError(f"{source}: invalid motion graph: {type(exc).__name__}: {exc}") from None

    def _payload(self) -> tuple[dict, dict]:
        """(arrays, metadata) of the graph and its source motion, as save writes them."""
        arrays = {**self.motion._to_arrays(), **self._to_arrays()}
        return arrays, {"dt": self.motion.dt, "params": _thaw(self.params), "provenance": _thaw(self.provenance)}

    @classmethod
    def _from_payload(cls, arrays, header, source) -> MotionGraph:
        """The inverse of :meth:`_payload`; FileFormatError naming `source`."""
        try:
            motion = Motion._from_arrays(arrays, header["dt"])
        except (KeyError, ValidationError) as exc:
            raise FileFormatError(f"{source}: invalid motion graph: {type(exc).__name__}: {exc}") from None
        return cls._from_arrays(arrays, motion, header.get("params"), header.get("provenance"), source)

    def save(self, path) -> None:
        """Write the graph and its source motion to one .npz with JSON metadata (atomic)."""
        arrays, metadata = self._payload()
        version = PLAIN_GRAPH_FORMAT_VERSION if self.period is None else GRAPH_FORMAT_VERSION
        _npzfile.write(path, kind="graph", version=version, arrays=arrays, metadata=metadata)

    @classmethod
    def load(cls, path) -> MotionGraph:
        """Read a graph written by :meth:`save`; FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(path, kind="graph", versions=(PLAIN_GRAPH_FORMAT_VERSION, GRAPH_FORMAT_VERSION))
        return cls._from_payload(arrays, header, path)


def turns(motion: Motion, frames, *, angle: float, blend: int) -> list[tuple[int, int, Alignment, int]]:
    """Turn transitions at source `frames`, as ``(frame, frame, alignment, blend)`` for
    :meth:`MotionGraph.assemble`: the motion from each frame rotated by +-`angle` degrees about
    the group's center of mass there (in 3D about the up axis, and about the horizontal axis
    across the group's heading, so that it can also climb and dive). Its blend steers the group
    onto the new heading over `blend` frames; its distance is the jump that blend absorbs, the
    mean squared distance between the configuration and its turned copy."""
    radians = np.radians(angle)
    found = []
    for frame in (int(f) for f in frames):
        configuration = motion.configuration(frame)
        center = configuration.center_of_mass()
        if motion.dims == 2:
            rotations = [rigid.rotation(radians), rigid.rotation(-radians)]
        else:
            across = heading_axes(configuration.velocities)[1]  # horizontal, left of the heading
            rotations = [rigid.rotation(s * radians, axis) for axis in (DEFAULT_UP, across) for s in (1, -1)]
        for r in rotations:
            identity = np.arange(motion.n_agents)
            turned = Alignment(distance=0.0, assignment=identity, rotation=r, translation=center - r @ center)
            distance = turned.residual(configuration, configuration)
            found.append((frame, frame, attrs.evolve(turned, distance=distance), blend))
    return found


# A seam's step or change of velocity may exceed the recording's own largest by this share and
# still count as one of its steps (loop_period; our choice: a glTF cycle's closing keyframes are
# within a few percent, a recording that merely ends near its start is off by far more).
LOOP_TOLERANCE = 0.25


def loop_period(motion: Motion, *, tolerance: float = LOOP_TOLERANCE) -> int | None:
    """The frames of one cycle if `motion` loops, else None.

    A motion loops with period T (its frame count) when its first frame follows its last as any
    frame follows the one before: the step across the seam, and the change of velocity on either
    side of it, are at most (1 + `tolerance`) times the largest step and change of velocity within
    the motion (every point's, in length units). It loops with period T - 1 when its last frame
    repeats its first (as a cycle whose closing keyframe equals its opening one does): they are at
    most `tolerance` times the largest step apart, and the motion runs on from frame T - 2 to
    frame 0 as smoothly. Where both hold, the smoother seam wins. A motion that never moves, or has
    fewer than 4 frames, does not loop."""
    if not isinstance(motion, Motion):
        raise ValidationError(f"loop_period needs a flockkit.Motion; got {type(motion).__name__}")
    x = motion.positions
    frames = len(x)
    if frames < 4:
        return None

    def largest(a):
        return float(np.linalg.norm(a, axis=-1).max())

    step = largest(np.diff(x, axis=0))
    if step == 0:
        return None
    change = largest(x[2:] - 2 * x[1:-1] + x[:-2])
    allowed_change = (1 + tolerance) * change + 1e-9 * step

    def seam(last: int) -> float:
        """The larger change of velocity where frame `last` runs on to frame 0."""
        return max(largest(x[0] - 2 * x[last] + x[last - 1]), largest(x[1] - 2 * x[0] + x[last]))

    found = []
    if largest(x[0] - x[-1]) <= (1 + tolerance) * step and seam(frames - 1) <= allowed_change:
        found.append((seam(frames - 1), frames))
    if frames >= 5 and largest(x[-1] - x[0]) <= tolerance * step and seam(frames - 2) <= allowed_change:
        found.append((seam(frames - 2), frames - 1))
    return min(found)[1] if found else None


def phase_shifts(motion: Motion, frames, *, sizes, blend: int, period: int | None = None):
    """Phase shifts leaving source `frames`, as ``(frame, frame + size, alignment, blend)`` for
    :meth:`MotionGraph.assemble`: for each size in `sizes` (frames on, > 0, or back, < 0), a
    transition to the same motion that much sooner or later (around the loop, with `period`),
    blended over `blend` frames. Its alignment is the identity and its distance the mean squared
    distance between the two configurations. Shifts a blend cannot hide (3 |size| > blend + 1,
    see MotionGraph.shifts) are refused; on a source that does not loop, shifts whose frames or
    blend would run past the recording are left out."""
    sizes = [int(size) for size in sizes]
    if any(size == 0 or 3 * abs(size) > blend + 1 for size in sizes):
        raise ValidationError(
            f"phase_shifts: every size must be non-zero and at most (blend + 1) / 3 = {(blend + 1) / 3:g} frames "
            f"for its blend to hide it; got {sizes}"
        )
    x = motion.positions
    identity = np.arange(motion.n_agents)
    found = []
    for frame in (int(f) for f in frames):
        for size in sizes:
            end = frame + size
            if period is not None:
                end %= period
            elif not (0 <= end < motion.n_frames and frame + blend < motion.n_frames):
                continue
            distance = float(np.mean(np.sum((x[frame] - x[end]) ** 2, axis=1)))
            alignment = Alignment(distance=distance, assignment=identity, rotation=np.eye(motion.dims),
                                  translation=np.zeros(motion.dims))  # fmt: skip
            found.append((frame, end, alignment, int(blend)))
    return found


def local_minima(values: np.ndarray, far: np.ndarray) -> list[tuple[int, int]]:
    """The local minima of a difference matrix `values` (K, K) where builders place transitions:
    cells (i, j), i != j, at most each of their 8 neighbors (the diagonal ignored), with far[i, j]."""
    rows, cols = np.nonzero(np.isfinite(values))
    minima = local_minima_of_cells(rows, cols, values[rows, cols], far[rows, cols])
    return [(int(i), int(j)) for i, j in minima]


def local_minima_of_cells(rows, cols, values, far) -> np.ndarray:
    """``local_minima`` of a difference matrix known only at cells (rows[m], cols[m]), every other
    cell +inf: shape (M, 2), in row-major order. Memory and time grow with the cells given, not with
    the matrix, so that builders of long recordings need not hold it whole."""
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64)
    if not len(rows):
        return np.zeros((0, 2), dtype=np.int64)
    base = int(max(rows.max(), cols.max())) + 3  # neighbors' indices run from -1 to max + 1
    keys = (rows + 1) * base + cols + 1
    order = np.argsort(keys)
    sorted_keys, sorted_values = keys[order], values[order]
    is_min = np.asarray(far, dtype=bool) & (rows != cols) & np.isfinite(values)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                wanted = keys + di * base + dj  # each cell's neighbor
                at = np.minimum(np.searchsorted(sorted_keys, wanted), len(keys) - 1)
                found = (sorted_keys[at] == wanted) & (rows + di != cols + dj)  # the diagonal counts as +inf
                is_min &= ~found | (values <= sorted_values[at])
    minima = np.flatnonzero(is_min)
    minima = minima[np.argsort(keys[minima])]
    return np.column_stack([rows[minima], cols[minima]])


def _clips(nodes, period: int | None = None) -> list[Clip]:
    """Clip k joins node k to node k + 1, playing the frames between them; with `period`, the
    last joins the last node to the first across the loop."""
    clips = [Clip(source=i, target=i + 1, start=int(nodes[i]), stop=int(nodes[i + 1])) for i in range(len(nodes) - 1)]
    if period is not None and len(nodes):
        clips.append(Clip(source=len(nodes) - 1, target=0, start=int(nodes[-1]), stop=int(nodes[0]) + period))
    return clips


def _period(value) -> int | None:
    if value is None:
        return None
    return integer(value, "MotionGraph.period", minimum=2)


def _shifts(graph) -> np.ndarray:
    """MotionGraph.shifts of `graph` (see there)."""
    t = graph.transitions
    if not t:
        return np.zeros(0, dtype=np.int64)
    start, end = np.array([x.start for x in t]), np.array([x.end for x in t])
    blend = np.array([x.blend for x in t])
    shift = end - start
    if graph.period is not None:  # around the loop: the nearer way
        shift = (shift + graph.period // 2) % graph.period - graph.period // 2
    d, n = graph.motion.dims, graph.motion.n_agents
    plain = np.array(
        [
            np.array_equal(x.alignment.rotation, np.eye(d))
            and not np.any(x.alignment.translation)
            and np.array_equal(x.alignment.assignment, np.arange(n))
            for x in t
        ]
    )
    return np.where(plain & (shift != 0) & (3 * np.abs(shift) <= blend + 1), shift, 0).astype(np.int64)


def _strongly_connected_frames(transitions) -> np.ndarray:
    """Frames of the largest strongly connected component (ties: the one with the earliest frame)
    of the graph whose nodes are the transition frames, joined in order by clips and by the
    transitions. Consecutive kept frames are joined by clips: a frame between two kept ones is
    reachable from one and reaches the other, so it is kept too."""
    frames = np.unique([f for start, end, _, _ in transitions for f in (start, end)])
    index = {int(f): i for i, f in enumerate(frames)}
    k = len(frames)
    rows = list(range(k - 1)) + [index[s] for s, _, _, _ in transitions]
    cols = list(range(1, k)) + [index[e] for _, e, _, _ in transitions]
    adjacency = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(k, k)).tocsr()
    _, labels = connected_components(adjacency, directed=True, connection="strong")
    sizes = np.bincount(labels)
    largest = min(np.flatnonzero(sizes == sizes.max()), key=lambda label: np.argmax(labels == label))
    nodes = frames[labels == largest]
    if len(nodes) < 2 and not any(s == e for s, e, _, _ in transitions):
        return np.array([], dtype=np.int64)
    return nodes
