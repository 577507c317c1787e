"""Motion graphs (paper 000 section 4.3, after Kovar et al.): clips of a source motion joined by
transitions between similar configurations.

A builder chooses transitions, pairs of source frames (leave at `start`, arrive at `end`) with the
metric's Alignment; :meth:`MotionGraph.assemble` turns them into a graph: every transition frame
is a node, consecutive nodes are joined by clips (frame ranges of the source), and dead ends are
trimmed by keeping the largest strongly connected component.
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

__all__ = ["MotionGraph", "Clip", "Transition", "Walk", "turns", "local_minima", "local_minima_of_cells"]

GRAPH_FORMAT_VERSION = 1


@attrs.frozen(kw_only=True)
class Clip:
    """An edge that plays source frames ``start..stop`` (both included) from node `source` to `target`.

    Attributes
    ----------
    source, target : int
        The nodes it joins: clip k of a MotionGraph joins node k to node k + 1.
    start, stop : int
        The source frames of those nodes (``graph.nodes[k]``, ``graph.nodes[k + 1]``), start < stop.
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


@attrs.frozen(kw_only=True, eq=False)
class Walk:
    """A path through a MotionGraph: where it starts, how the source is placed, and its edges.

    Its length is that of the motion it plays, ``flockkit.synthesize(graph, walk)``: the start
    node's frame, then for each ``("clip", k)`` the clip's frames after its first
    (``clip.n_frames - 1``); a transition plays no frame of its own (the next clip carries on from
    its target, blended over ``transition.blend`` frames). Its duration in seconds is (frames
    played - 1) x the source's dt: a walk strategy asked for `duration` returns a walk at least
    that long.

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
        (a proper (D, D) rotation and a (D,) vector; None: the identity).
    """

    start: int = attrs.field(converter=lambda v: integer(v, "Walk.start", minimum=0))
    edges: tuple = attrs.field(converter=lambda edges: tuple(_edge(e) for e in _sequence(edges, "Walk.edges")))
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
        object.__setattr__(
            self, "_is_transition", np.array([kind == "transition" for kind, _ in self.edges], dtype=bool)
        )
        object.__setattr__(self, "_index", np.array([index for _, index in self.edges], dtype=np.int64))

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

    @classmethod
    def of(cls, graph) -> EdgeTables:
        t = graph.transitions
        return cls(
            clip_start=np.array([c.start for c in graph.clips], dtype=np.int64),
            clip_stop=np.array([c.stop for c in graph.clips], dtype=np.int64),
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
        Clip k joins node k to node k + 1.
    transitions : tuple of Transition
    params : mapping
        The builder's parameters, as JSON values (threshold chosen, candidate stride, ...).
    provenance : mapping
        Metric, builder, flockkit version and seed, as JSON values.
    """

    motion: Motion
    nodes: np.ndarray = attrs.field(converter=lambda v: readonly_int(v, field="MotionGraph.nodes"))
    clips: tuple = attrs.field(converter=tuple)
    transitions: tuple = attrs.field(converter=tuple)
    params: Mapping = attrs.field(factory=dict, converter=lambda v: _frozen_json(v, "MotionGraph.params"))
    provenance: Mapping = attrs.field(factory=dict, converter=lambda v: _frozen_json(v, "MotionGraph.provenance"))
    _tables: EdgeTables = attrs.field(init=False, repr=False, eq=False)

    def __attrs_post_init__(self):
        self._validate()
        object.__setattr__(self, "_tables", EdgeTables.of(self))

    @property
    def tables(self) -> EdgeTables:
        """The edges as arrays, for vectorized walking and playback."""
        return self._tables

    def _validate(self):
        k, frames = len(self.nodes), self.motion.n_frames
        if (
            k < 1
            or self.nodes.ndim != 1
            or np.any(np.diff(self.nodes) <= 0)
            or self.nodes[0] < 0
            or self.nodes[-1] >= frames
        ):
            raise ValidationError(
                f"MotionGraph.nodes must be increasing source frames in 0..{frames - 1}; got {self.nodes}"
            )
        for index, clip in enumerate(self.clips):
            if (clip.source, clip.target, clip.start, clip.stop) != (index, index + 1, *self.nodes[index : index + 2]):
                raise ValidationError(
                    f"MotionGraph.clips[{index}] must join node {index} to node {index + 1} by their frames"
                )
        if len(self.clips) != k - 1:
            raise ValidationError(f"MotionGraph needs {k - 1} clips for {k} nodes; got {len(self.clips)}")
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
            if transition.start + transition.blend > frames - 1:
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
    ) -> MotionGraph:
        """Build a graph from transitions ``(start_frame, end_frame, alignment, blend)``: nodes at
        every transition frame, clips between consecutive nodes, trimmed to the largest strongly
        connected component (ties: the one holding the earliest frame). Transitions that land less
        than the longest blend before the last kept frame, or leave less than their blend before the
        recording's end (the motion they blend away from runs out), are dropped (and the trimming
        repeated), so a walk can always continue and be played.

        Raises ValidationError if no transitions are given (a graph needs at least one loop).
        """
        if not transitions:
            raise ValidationError(
                "no transitions: the recording has no pair of similar configurations under the builder's "
                "threshold; raise the threshold or record longer motion"
            )
        transitions = list(transitions)
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
        return edges + [("transition", i) for i, t in enumerate(self.transitions) if t.source == node]

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
        return int(self.nodes[-1] - self.nodes[0] + 1) if len(self.clips) else 1

    def stats(self) -> dict:
        """Plain numbers describing the graph; equal graphs give equal dicts."""
        distances = np.array([t.alignment.distance for t in self.transitions if not t.is_turn])
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
        )

    __hash__ = None

    # -- files -----------------------------------------------------------------------------

    def _to_arrays(self) -> dict[str, np.ndarray]:
        """The graph's own arrays (its motion's are written separately)."""
        tables = self.tables
        return {
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
            return cls(motion=motion, nodes=nodes, clips=_clips(nodes), transitions=transitions, params=params,
                       provenance=provenance)  # fmt: skip
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
        _npzfile.write(path, kind="graph", version=GRAPH_FORMAT_VERSION, arrays=arrays, metadata=metadata)

    @classmethod
    def load(cls, path) -> MotionGraph:
        """Read a graph written by :meth:`save`; FileFormatError naming the file if it is not one."""
        arrays, header = _npzfile.read(path, kind="graph", versions=(GRAPH_FORMAT_VERSION,))
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


def _clips(nodes) -> list[Clip]:
    """Clip k joins node k to node k + 1, playing the frames between them."""
    return [Clip(source=i, target=i + 1, start=int(nodes[i]), stop=int(nodes[i + 1])) for i in range(len(nodes) - 1)]


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
