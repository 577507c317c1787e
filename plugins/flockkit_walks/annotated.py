"""Walks that follow a target feature track (paper 002, section 6.1).

The walk minimizes E = C_T + alpha C_C + beta N_T over the output frames it must cover:

- C_T, the transition cost: the distances of the transitions taken, each divided by the median
  distance of the graph's transitions (so one ordinary transition costs about 1 on any graph; of
  those above 0 where most are 0, as a looping source's exact repeats are);
- C_C, the constraint cost: the distance between the played feature arrow (the source frame's
  arrow, turned with the walk) and the target arrow, summed over output frames times dt (so a
  mismatch of 0.1 for one second costs 0.1, whatever the frame rate);
- N_T, the number of transitions.

Phase shifts (``MotionGraph.shifts``: a transition to the same motion a frame or two sooner or
later, which its blend hides, as a builder adds to a short cycle) are neither in C_T nor in N_T:
they keep the motion continuous and only let its timing drift. The initial pass prefers a phase
shift it has not taken yet to going straight on, and going straight on (a clip, after which other
phase shifts leave) to a phase shift it has taken (each costs `vary` more than the one before it),
so that a short cycle wavers in time without playing any blend twice while it can. It keeps
within `drift` frames of the timing it started with, so that walks started out of step stay so;
the target and the walks to avoid still come first. With walks to avoid, a drifting walk's
start is judged over its whole length, being in step counts over the next two blends only (after
a blend it may shift away again), and on a loop crowded by them it drifts less (see `drift`).

An initial pass starts where the source's arrows meet the first target (a random node among
those that do), then takes, at each node, the edge whose next two seconds best follow the target
(those within TIE of the best chosen among at random). Then repeated subsequence replacement
(Schoedl and Essa 2002): pick a stretch of `segment` seconds whose share of E per second
exceeds `threshold`, search the alternative paths between its ends (up to two transitions, as
long give or take half a segment) and keep the best if it lowers E, until no stretch is above
the threshold, no replacement helps, or `budget` attempts are spent.
"""

from __future__ import annotations

import math
import weakref

import attrs
import numpy as np
from scipy.spatial import cKDTree

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError
from flockkit.scene import Features, interpolate_arrows

from . import _kernels

# Look-ahead costs this close (as a mean arrow error) count as a tie in the initial pass, broken
# at random (our choice, measured on bench/scene.py: neighbours in step on 27% of frames before
# section 6.2 instead of 99%, frames within 0.2 of the target 98.6% instead of 99.3%).
TIE = 0.02

# Whether walks on graphs that do not turn run their first pass and replacement searches as the
# compiled loops of _kernels (the same walks, edge for edge); False runs the Python reference.
_COMPILED = True


def _target(value):
    return value if isinstance(value, (Features, _Keyframes)) else _Keyframes(value)


@attrs.frozen(eq=False)
class _Keyframes:
    """Keyframed target arrows, checked as Features.from_keyframes checks them."""

    keyframes: tuple = attrs.field(converter=lambda v: _checked_keyframes(v))

    def at(self, times) -> np.ndarray:
        return interpolate_arrows(*self.keyframes, times)


def _checked_keyframes(value):
    return flockkit.scene.arrow_keyframes(value, "walk parameter target")


def _track(target, times) -> np.ndarray:
    """Target arrows (len(times), D) at `times`: keyframes interpolated, Features per frame at
    its own dt (held after its last frame)."""
    if isinstance(target, Features):
        index = np.minimum(np.round(np.asarray(times) / target.dt).astype(np.int64), target.n_frames - 1)
        return np.asarray(target.vectors)[index]
    return target.at(times)


def _avoid(value):
    if value is None:
        return None
    array = np.asarray(value)
    if array.ndim != 2 or not np.issubdtype(array.dtype, np.integer):
        raise ValidationError(
            f"walk parameter avoid must be an integer array (walks, frames); got {array.dtype} {array.shape}"
        )
    return array


def _pad(vectors: np.ndarray, dims: int, name: str) -> np.ndarray:
    """Arrows in `dims` coordinates: 2D arrows of a 3D graph lie in the ground plane (z = 0)."""
    if vectors.shape[1] == dims:
        return vectors
    if vectors.shape[1] == 2 and dims == 3:
        return np.column_stack([vectors, np.zeros(len(vectors))])
    raise ValidationError(f"walk parameter {name} has {vectors.shape[1]}D arrows; the graph is {dims}D")


def _same_array(a, b) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def _features(value):
    if value is not None and not isinstance(value, Features):
        raise ValidationError(
            "walk parameter features must be flockkit.Features of the graph's source, or None; "
            f"got {type(value).__name__}"
        )
    return value


@attrs.frozen(kw_only=True)
class AnnotatedWalk:
    """A walk whose played feature arrows follow `target` (paper 002, section 6.1).

    Parameters
    ----------
    target : flockkit.Features or [(time, vector), ...]
        The target arrow over the walk's time: Features with one arrow per output frame (its dt
        the graph's), or keyframes interpolated as Features.from_keyframes does.
    features : flockkit.Features, optional
        The arrows of the graph's source frames (GraphLayers.features for a part of a layered
        object); None derives them from the motion (Features.from_motion: speed and heading).
    alpha : float
        Weight of the constraint cost C_C against the transition cost C_T (default 10: a
        mismatch of 0.1 held for one second weighs as much as one ordinary transition).
    beta : float
        Cost of each transition (N_T); larger means fewer transitions (default 1).
    segment : float
        Seconds of the stretches that subsequence replacement picks (default 2).
    threshold : float
        A stretch whose share of E per second exceeds this is worth replacing (default 0.5: one
        ordinary transition every 4 s, or a mismatch of 0.05 held).
    budget : int
        Replacement attempts at most (default 20; 0: the initial pass alone).
    reach : float
        A target farther than this from every arrow the graph plays (its kept source frames;
        length units of arrows) is refused before walking, with how close it gets (default 0.5).
    start : int, optional
        Start node (None: a random node among those that meet the first target).
    avoid : int array (K, F), optional
        Source frames other walks of the same graph play at each output frame (-1: none; a row
        of -1 is a walk yet to be made, which will avoid this one: it counts for the room a loop
        leaves, see `drift`). Each output frame that plays within one frame of one of them (around
        the loop, on a looping graph) adds `in_step` to its feature error, so the walk falls out
        of step with them (the neighbour optimization of paper 002, section 6.2).
    in_step : float
        The error of a frame in step with an avoided walk (default 1).
    vary : float
        In the initial pass, the extra cost of going straight on where a phase shift not taken
        yet is allowed, and of taking a phase shift taken before (default 0.5: above its random
        tie-break, below one frame in step with an avoided walk).
    drift : int
        Frames at most by which the initial pass's phase shifts move the walk's timing from its
        start's, either way (default 2): its timing wavers, but a walk started out of step with
        its neighbours stays so. On a loop of P frames shared with K walks to avoid, at most
        (P / (K + 1) - 1) / 2, and at least 1: walks drifting that much each, started 2 drift +
        1 frames apart, come within a frame of each other only by both drifting all the way
        towards each other.
    """

    # takes target, features and avoid: the walks a flockkit.Scene makes
    capabilities = flockkit.Capabilities(targets=True)

    target: object = attrs.field(converter=_target)
    features: Features | None = attrs.field(default=None, converter=_features)
    alpha: float = validate.parameter("annotated", default=10.0, minimum=0)
    beta: float = validate.parameter("annotated", default=1.0, minimum=0)
    segment: float = validate.parameter("annotated", default=2.0, minimum=0, strict=True)
    threshold: float = validate.parameter("annotated", default=0.5, minimum=0)
    budget: int = validate.parameter("annotated", default=20, kind="integer", minimum=0)
    reach: float = validate.parameter("annotated", default=0.5, minimum=0, strict=True)
    start: int | None = validate.parameter("annotated", default=None, kind="integer", minimum=0, optional=True)
    avoid: np.ndarray | None = attrs.field(default=None, converter=_avoid, eq=attrs.cmp_using(eq=_same_array))
    in_step: float = validate.parameter("annotated", default=1.0, minimum=0)
    vary: float = validate.parameter("annotated", default=0.5, minimum=0)
    drift: int = validate.parameter("annotated", default=2, kind="integer", minimum=0)

    def walk(self, graph: flockkit.MotionGraph, rng: np.random.Generator, duration: float) -> flockkit.Walk:
        problem = _Problem(self, graph, duration)
        path = problem.initial(rng)
        attempts, tried = 0, set()
        while attempts < self.budget:
            choice = problem.pick(path, rng, tried)
            if choice is None:
                break
            attempts += 1
            better = problem.replace(path, *choice)
            if better is None:
                tried.add(choice)
            else:
                path, tried = better, set()
        return flockkit.Walk(start=path.start, edges=path.edges)

    def energy(self, graph: flockkit.MotionGraph, walk: flockkit.Walk, duration: float | None = None) -> dict:
        """{"E", "C_T", "C_C", "N_T"} of `walk` over `duration` seconds (default: all it plays)."""
        if duration is None:
            duration = len(flockkit.graphs.played_frames(graph, walk)[0]) * graph.motion.dt
        problem = _Problem(self, graph, duration)
        return problem.path(walk.start, list(walk.edges)).report()


class _Path:
    """A walk being improved, laid out per edge and per output frame."""

    def __init__(self, problem, start, edges):
        self.problem, self.start, self.edges = problem, start, edges
        self.stretches = None  # what pick weighs, made at its first pick
        # per edge, and after the last: the node it leaves, its first output frame, clip frames
        # since the last transition and the rotation (as problem.step goes, all at once)
        is_transition = np.array([kind == "transition" for kind, _ in edges], dtype=bool)
        index = np.array([i for _, i in edges], dtype=np.int64)
        played = np.where(is_transition, 0, problem.clip_frames[np.where(is_transition, 0, index)])
        at = np.concatenate([[0], np.cumsum(played)])
        taken = np.concatenate([[0], np.cumsum(is_transition)])  # transitions before each edge
        after = at[1:][is_transition]  # output frame at each transition taken
        since = np.where(taken > 0, at - after[np.maximum(taken - 1, 0)] if len(after) else 0, np.inf)
        last = problem.graph.edge_target(edges[-1]) if edges else start
        sources = index.copy()
        sources[is_transition] = problem.trans_source[index[is_transition]]
        self.node, self.at, self.since = [*sources.tolist(), last], at.tolist(), since.tolist()
        self.transitions_taken = np.flatnonzero(is_transition)  # the edges that are transitions
        if problem.rotating:
            self.rotation = [np.eye(problem.dims)]
            for edge in edges:
                self.rotation.append(problem.step((0, 0, 0, self.rotation[-1]), edge)[3])
        else:
            self.rotation = [np.eye(problem.dims)] * (len(edges) + 1)
        # the source frame each output frame plays, as synthesis plays it (flockkit.graphs.played_frames):
        # each clip's frames but its last, then the frame of the node the walk ends at
        clips = np.flatnonzero(~is_transition)
        lengths = problem.clip_frames[index[clips]]
        first = problem.nodes[index[clips]]
        self.frames = problem.wrap(
            np.append(np.repeat(first - np.cumsum(lengths) + lengths, lengths) + np.arange(lengths.sum()),
                      problem.nodes[self.node[-1]])
        )  # fmt: skip
        self.played = problem.features[self.frames]
        if problem.rotating:
            rotations = np.stack([self.rotation[k] for k in clips] + [self.rotation[-1]])
            turned = np.append(np.repeat(np.arange(len(clips)), lengths), len(clips))
            self.played = np.einsum("fij,fj->fi", rotations[turned], self.played)
        n = min(len(self.frames), problem.needed)
        self.error = np.zeros(problem.needed)
        self.error[:n] = problem.frame_error(self.played[:n], self.frames[:n], 0)
        # each edge's share of C_T + beta N_T, and its running sum (what pick weighs stretches by)
        transitions = index[is_transition]
        ordinary = problem.shift[transitions] == 0
        self.edge_cost = np.zeros(len(edges))
        self.edge_cost[is_transition] = problem.trans_cost[transitions] + problem.beta * ordinary
        self.running_cost = np.concatenate([[0.0], np.cumsum(self.edge_cost)])
        taken = transitions[ordinary]
        self.c_t = float(problem.trans_cost[taken].sum())
        self.n_t = len(taken)

    def report(self) -> dict:
        """E and its terms; C_C counts feature error only, in_step frames are reported apart."""
        p = self.problem
        n = min(len(self.frames), p.needed)
        c_c = float(np.linalg.norm(self.played[:n] - p.track[:n], axis=1).sum() * p.dt)
        in_step = int(np.count_nonzero(p.in_step_frames(self.frames[:n], 0))) if p.avoid is not None else 0
        energy = self.c_t + p.alpha * (c_c + p.in_step * in_step * p.dt) + p.beta * self.n_t
        return {"E": energy, "C_T": self.c_t, "C_C": c_c, "N_T": self.n_t, "in_step_frames": in_step}


class _Shared:
    """What every annotated walk of one graph needs (with one beta), made once: edge tables,
    each node's choices, and errors remembered under constant targets."""

    REMEMBERED = 200_000  # entries per arrows and weights before the memo starts afresh

    def __init__(self, graph, beta: float):
        tables = graph.tables
        dims = graph.motion.dims
        self.nodes = np.asarray(graph.nodes)
        self.clip_frames = tables.clip_stop - tables.clip_start
        self.trans_rotation = tables.rotation
        self.trans_target = tables.transition_target
        self.trans_source = tables.transition_source
        self.rotating = len(graph.transitions) > 0 and not np.allclose(tables.rotation, np.eye(dims))
        self.period, self.shift, self.clip_target = graph.period, tables.shift, tables.clip_target
        distance = np.array([t.alignment.distance for t in graph.transitions])
        ordinary = [t.alignment.distance for t, s in zip(graph.transitions, self.shift) if not t.is_turn and not s]
        # the unit of C_T: the median ordinary distance, or, where most are 0 (a looping source's
        # exact repeats), the median of those above 0, so the others still cost what they differ
        positive = [d for d in ordinary if d > 0]
        scale = float(np.median(ordinary)) if ordinary else 0.0
        scale = scale if scale > 0 or not positive else float(np.median(positive))
        self.trans_cost = distance / scale if scale > 0 else np.zeros(len(distance))
        self.trans_cost[self.shift != 0] = 0.0  # phase shifts keep the motion continuous: no C_T, no N_T
        # frames after a transition before the next: its blend, and at least one (two transitions with
        # no frame between are one jump, and with blends of 0 a search could chain them for ever)
        self.longest = max(int(tables.transition_blend.max()), 1) if len(graph.transitions) else 0
        self.out = [[] for _ in self.nodes]
        for index, t in enumerate(graph.transitions):
            self.out[t.source].append(index)
        self.n_clips = len(graph.clips)
        # per node: its edges (the clip first, if any), the node each looks ahead from (a clip
        # goes straight on from here) and its fixed cost (C_T + beta for a transition)
        self.choices = []
        for node, out in enumerate(self.out):
            clip = [("clip", node)] if node < self.n_clips else []
            edges = clip + [("transition", i) for i in out]
            targets = np.array([node] * len(clip) + [int(self.trans_target[i]) for i in out], dtype=np.int64)
            fixed = np.array([0.0] * len(clip) + [self.trans_cost[i] + beta * (not self.shift[i]) for i in out])
            self.choices.append((edges, targets, fixed))
        # per node: which of its edges are phase shifts (what _monotony weighs)
        self.shifts_here = [np.array([kind == "transition" and bool(self.shift[i]) for kind, i in edges], dtype=bool)
                            for edges, _, _ in self.choices]  # fmt: skip
        # the same, laid out for the compiled loops (_kernels): padded per node, kind 0 clip, 1 transition
        width = max(len(edges) for edges, _, _ in self.choices) if self.choices else 0
        self.edge_kind = np.full((len(self.nodes), width), -1, dtype=np.int64)
        self.edge_index = np.zeros((len(self.nodes), width), dtype=np.int64)
        self.edge_ahead = np.zeros((len(self.nodes), width), dtype=np.int64)
        self.edge_fixed = np.zeros((len(self.nodes), width))
        self.n_edges = np.array([len(edges) for edges, _, _ in self.choices], dtype=np.int64)
        for node, (edges, targets, fixed) in enumerate(self.choices):
            count = len(edges)
            self.edge_kind[node, :count] = [kind == "transition" for kind, _ in edges]
            self.edge_index[node, :count] = [index for _, index in edges]
            self.edge_ahead[node, :count], self.edge_fixed[node, :count] = targets, fixed
        self.out_table = np.zeros((len(self.nodes), max(map(len, self.out), default=0)), dtype=np.int64)
        self.out_count = np.array([len(out) for out in self.out], dtype=np.int64)
        for node, out in enumerate(self.out):
            self.out_table[node, : len(out)] = out
        self.shift_steps = np.asarray(self.shift, dtype=np.int64)
        self._memos = {}
        self._arrows = None  # the graph's distinct source arrows (see _Problem._tables)
        self.reach = {}  # the distinct arrows the graph plays, by source arrows (see _Problem._check_reach)

    def remembered(self, features: np.ndarray, alpha: float) -> dict:
        """The memo of errors under constant targets for these source arrows and alpha."""
        key = (features.tobytes(), alpha)
        memo = self._memos.setdefault(key, {})
        if len(memo) > self.REMEMBERED:
            memo.clear()
        return memo


_SHARED = {}  # id(graph) -> (weak reference to the graph, {beta: _Shared}), dropped with the graph


def _shared(graph, beta: float) -> _Shared:
    entry = _SHARED.get(id(graph))
    if entry is None or entry[0]() is not graph:
        entry = _SHARED[id(graph)] = (weakref.ref(graph), {})
        weakref.finalize(graph, _SHARED.pop, id(graph), None)
    by_beta = entry[1]
    if beta not in by_beta:
        by_beta[beta] = _Shared(graph, beta)
    return by_beta[beta]


class _Problem:
    """One graph, one source feature track and one target track: what both passes need."""

    SEARCH_NODES = 200  # nodes a replacement search expands at most
    MAX_TRANSITIONS = 2  # transitions in a replacement at most

    def __init__(self, strategy: AnnotatedWalk, graph, duration):
        if not isinstance(graph, flockkit.MotionGraph):
            raise ValidationError(f"a walk needs a flockkit.MotionGraph; got {type(graph).__name__}")
        duration = validate.number(duration, "walk duration (seconds)", minimum=0, strict=True)
        motion = graph.motion
        self.graph, self.alpha, self.beta = graph, strategy.alpha, strategy.beta
        self.dt, self.dims = motion.dt, motion.dims
        self.needed = math.ceil(duration / self.dt)
        validate.allocation(4 * self.needed * motion.dims * 3, f"an annotated walk of {duration:g} s")
        features = strategy.features if strategy.features is not None else Features.from_motion(motion)
        if features.n_frames != motion.n_frames:
            raise ValidationError(
                f"walk parameter features has {features.n_frames} arrows; "
                f"the graph's source has {motion.n_frames} frames"
            )
        self.features = _pad(np.asarray(features.vectors), self.dims, "features")
        self.track = _pad(_track(strategy.target, np.arange(self.needed) * self.dt), self.dims, "target")
        shared = _shared(graph, self.beta)
        self.nodes, self.clip_frames, self.trans_cost, self.longest = (
            shared.nodes,
            shared.clip_frames,
            shared.trans_cost,
            shared.longest,
        )
        self.trans_rotation, self.trans_target, self.trans_source = (
            shared.trans_rotation,
            shared.trans_target,
            shared.trans_source,
        )
        self.rotating, self.out, self.choices = shared.rotating, shared.out, shared.choices
        self.shifts_here, self.shared = shared.shifts_here, shared
        self.period, self.shift, self.n_clips = shared.period, shared.shift, shared.n_clips
        self.clip_target = shared.clip_target
        self.vary, self.drift = strategy.vary, strategy.drift
        # frames ahead over which being in step with an avoided walk counts: with phase shifts, two
        # blends (after one, the walk may shift away again); without, the whole look-ahead
        self.react = 2 * self.longest if self.shift.any() else None
        self.segment_frames = max(2, round(strategy.segment / self.dt))
        self.threshold = strategy.threshold
        # frames played straight on from each node over the next two seconds or the longest clip
        # (held at the last kept frame): the initial pass sees a wrong turn before it is committed
        self.ahead = max(2, round(2.0 / self.dt), int(self.clip_frames.max()) if len(self.clip_frames) else 0)
        # options whose look-ahead costs within a mean arrow error of TIE of the best's are
        # chosen among at random, so duplicates following one target do not all play alike
        self.noise = TIE * self.alpha * self.dt * self.ahead
        if self.period is None:
            self.straight = np.minimum(self.nodes[:, None] + np.arange(self.ahead), self.nodes[-1])
        else:  # round the loop
            self.straight = (self.nodes[:, None] + np.arange(self.ahead)) % self.period
        self._check_reach(strategy.reach)
        self.start = strategy.start
        # runs of output frames with one target arrow: an error over a window inside a run does
        # not depend on where in the run it lies, so it is remembered per target arrow (see _memo)
        change = np.any(np.diff(self.track, axis=0) != 0, axis=1)
        self.run = np.concatenate([[0], np.cumsum(change)])
        self.run_end = np.concatenate([np.flatnonzero(change), [self.needed - 1]])[self.run]
        self.avoid, self.in_step = strategy.avoid, strategy.in_step
        if self.avoid is not None and self.period is not None and self.shift.any():
            # as far as the loop's room for this walk and those it avoids allows (see `drift`)
            room = self.period / (len(self.avoid) + 1)
            self.drift = min(self.drift, max(1, int((room - 1) // 2)))
        # errors over windows of one target arrow are the same for every walk of this graph with
        # these arrows and weights: remembered across walks (a scene's duplicates share them);
        # windows where the target changes, or walks that avoid others, are remembered per walk
        self._per_walk = {}
        self._per_run = shared.remembered(self.features, self.alpha) if self.avoid is None else {}
        if self.avoid is not None and self.avoid.shape[1] < self.needed:
            raise ValidationError(
                f"walk parameter avoid covers {self.avoid.shape[1]} frames; the walk needs {self.needed}"
            )
        self._tables()

    def _tables(self) -> None:
        """Where the graph does not turn, the played arrow of a source frame is its own arrow, so
        frame_error needs no played arrows: the compiled loops (_kernels) compute each error from
        the source and target arrows where they need it, and the Python reference looks it up in
        a table made once per walk, the error of each distinct source arrow against each run of
        one target arrow (error_table[arrow_of[frame], run[t]]); both, where walks are avoided,
        look up whether in step with one (within one frame, around the loop) in step_table. Each
        error is the value frame_error computes (the same norm of the same difference), so walks
        are the same."""
        self.error_table = self.step_table = None
        self.compiled = False
        if self.rotating or self.needed == 0:
            return
        if self.avoid is not None:
            self.step_table = self._step_table()
        self.compiled = _COMPILED and (self.avoid is None or self.step_table is not None)
        if self.compiled:
            return
        if self.shared._arrows is None or not np.array_equal(self.shared._arrows[0], self.features):
            arrows, arrow_of = np.unique(self.features, axis=0, return_inverse=True)
            self.shared._arrows = (self.features, arrows, arrow_of.ravel())
        _, arrows, self.arrow_of = self.shared._arrows
        targets = self.track[np.flatnonzero(np.append(True, np.diff(self.run)))]  # one per run of one arrow
        # (distinct arrows, runs of one target arrow): output frame t's column is run[t]
        self.error_table = np.linalg.norm(arrows[:, None, :] - targets[None, :, :], axis=2)

    def _step_table(self) -> np.ndarray | None:
        """(source frames, output frames): whether a source frame played then is within one
        frame of an avoided walk's (around the loop); None where the walks avoided play frames
        no walk of this graph plays (left to in_step_frames)."""
        frames = len(self.features)
        others = self.avoid[:, : self.needed]
        valid = others >= 0
        if np.any(others >= (frames if self.period is None else self.period)):
            return None
        table = np.zeros((frames, self.needed), dtype=bool)
        columns = np.broadcast_to(np.arange(self.needed), others.shape)[valid]
        for step in (-1, 0, 1):
            near = others[valid] + step
            if self.period is not None:
                near %= self.period
            inside = (near >= 0) & (near < frames)
            table[near[inside], columns[inside]] = True
        return table

    def _table_error(self, frames, t) -> np.ndarray:
        """frame_error of `frames` (..., m) played from output frame t, from the tables."""
        columns = t + np.arange(frames.shape[-1])
        error = self.error_table[self.arrow_of[frames], self.run[columns]]
        if self.avoid is not None:
            error += self.in_step * self._in_step_table(frames, columns)
        return error

    def _in_step_table(self, frames, columns) -> np.ndarray:
        if self.step_table is None:
            return self.in_step_frames(frames, int(columns[0]) if len(columns) else 0)
        return self.step_table[frames, columns]

    def wrap(self, frames: np.ndarray) -> np.ndarray:
        """Source frames for frames counted on across the loop of a looping graph."""
        return frames if self.period is None else frames % self.period

    def in_step_frames(self, frames, t, within: int = 1) -> np.ndarray:
        """Whether each of `frames` (..., m: source frames played from output frame t on) is
        within `within` source frames of an avoided walk's (around the loop, on a looping graph)."""
        others = self.avoid[:, t : t + frames.shape[-1]]
        others = others.reshape(len(others), *[1] * (frames.ndim - 1), -1)
        apart = np.abs(others - frames)
        if self.period is not None:
            apart = np.minimum(apart, self.period - apart % self.period)
        return np.any((others >= 0) & (apart <= within), axis=0)

    def frame_error(self, played, frames, t) -> np.ndarray:
        """Per output frame from t: the feature error, plus in_step where in step with an avoided walk."""
        if self.error_table is not None:
            return self._table_error(frames[: len(played)], t)
        error = np.linalg.norm(played - self.track[t : t + len(played)], axis=1)
        if self.avoid is not None:
            error += self.in_step * self._in_step_table(frames, t + np.arange(frames.shape[-1]))
        return error

    def _check_reach(self, reach):
        def shape(vectors):  # with turns only the length (and the vertical part) is fixed
            if not self.rotating:
                return vectors
            if self.dims == 2:
                return np.linalg.norm(vectors, axis=1, keepdims=True)
            return np.column_stack([np.linalg.norm(vectors[:, :2], axis=1), vectors[:, 2]])

        # the frames the graph plays: its kept part of the source, or the whole loop
        first, last = (int(self.nodes[0]), int(self.nodes[-1])) if self.period is None else (0, self.period - 1)
        # first by the distinct arrows the graph plays (made once per graph and source arrows; a
        # source that holds one arrow plays one), with a margin for the rounding of a tree's
        # distances; only a target that comes near the reach or beyond is looked at again
        key = (self.features.tobytes(), self.rotating, first, last)
        if key not in self.shared.reach:
            arrows = np.unique(shape(self.features[first : last + 1]), axis=0)
            self.shared.reach = {key: (arrows, cKDTree(arrows) if len(arrows) > 8 else None)}
        arrows, tree = self.shared.reach[key]
        points = shape(self.track)
        if tree is not None:
            nearest = tree.query(points)[0]
        else:
            nearest = np.min([np.linalg.norm(points - arrow, axis=1) for arrow in arrows], axis=0)
        if len(nearest) and nearest.max() <= reach - 1e-9:
            return
        closest, index = cKDTree(shape(self.features[first : last + 1])).query(points)
        index = index + first
        worst = int(np.argmax(closest))
        if closest[worst] > reach:
            raise ValidationError(
                f"walk parameter target: at t={worst * self.dt:g} s the target arrow "
                f"{np.round(self.track[worst], 3).tolist()} is {closest[worst]:.3g} from the closest arrow the graph "
                f"plays ({np.round(self.features[index[worst]], 3).tolist()} at source frame {int(index[worst])}); "
                f"the walk can come no closer than that (reach is {reach:g})"
            )

    def path(self, start, edges) -> _Path:
        return _Path(self, start, edges)

    def step(self, state, edge):
        """(node, output frame, clip frames since the last transition, rotation) after `edge`."""
        node, t, since, rotation = state
        kind, index = edge
        if kind == "clip":
            return int(self.clip_target[index]), t + self.clip_frames[index], since + self.clip_frames[index], rotation
        turned = rotation @ self.trans_rotation[index] if self.rotating else rotation
        return self.trans_target[index], t, 0, turned

    def _lookahead(self, targets, rotations, t) -> np.ndarray:
        """Error of going straight on from each of `targets` (nodes), turned by `rotations`, from
        output frame t (frame_error summed over the look-ahead, times dt)."""
        track = self.track[t : t + self.ahead]
        frames = self.straight[targets][:, : len(track)]
        if self.error_table is not None and rotations is None:
            columns = t + np.arange(frames.shape[1])
            error = self.error_table[self.arrow_of[frames], self.run[columns]]
            if self.avoid is not None:
                react = frames.shape[1] if self.react is None else self.react
                error[:, :react] += self.in_step * self._in_step_table(frames[:, :react], columns[:react])
            return error.sum(axis=1) * self.dt
        played = self.features[frames]
        if rotations is not None:
            played = np.einsum("kij,khj->khi", rotations, played)
        error = np.linalg.norm(played - track, axis=2)
        if self.avoid is not None:
            react = self.react
            error[:, :react] += self.in_step * self.in_step_frames(frames[:, :react], t)
        return error.sum(axis=1) * self.dt

    def initial(self, rng) -> _Path:
        if self.start is not None:
            if self.start >= len(self.nodes):
                raise ValidationError(f"walk start must be a node index in 0..{len(self.nodes) - 1}; got {self.start}")
            node = self.start
        else:
            node = self._start(rng)
        if self._compiled():
            return self.path(node, self._initial_compiled(rng, node))
        start, edges, shifted, drifted = node, [], set(), 0
        state = (node, 0, math.inf, np.eye(self.dims))
        while state[1] < self.needed:
            node, t, since, rotation = state
            all_edges, all_targets, all_fixed = self.choices[node]
            if since < self.longest:  # no transition until the last blend has played out: the clip alone
                keep = [0] if node < self.n_clips else []
            else:  # phase shifts only while they keep the timing within `drift` frames of the start's
                keep = [k for k, (kind, i) in enumerate(all_edges)
                        if kind == "clip" or abs(drifted + self.shift[i]) <= self.drift]  # fmt: skip
            if not keep:
                raise ValidationError(
                    f"annotated walk: node {node} has no edge to take {since} frames after a transition"
                )
            edges_here = [all_edges[k] for k in keep]
            if len(edges_here) == 1:
                rng.random(1)  # the draw a choice among several would take, so the stream stays the same
                edge = edges_here[0]
            else:
                targets, fixed = all_targets[keep], all_fixed[keep]
                if self.rotating:
                    rotations = np.stack(
                        [rotation if kind == "clip" else rotation @ self.trans_rotation[i] for kind, i in edges_here]
                    )
                    cost = self.alpha * self._lookahead(targets, rotations, t) + fixed
                else:  # remembered per node, choices and target window, as clip errors are
                    memo, window = self._memo(t, self.ahead)
                    key = ("ahead", node, len(all_edges), window)
                    if key not in memo:
                        memo[key] = self.alpha * self._lookahead(all_targets, None, t) + all_fixed
                    cost = memo[key][keep]
                cost = cost + self._monotony(edges_here, shifted, self.shifts_here[node][keep])
                edge = edges_here[int(np.argmin(cost + self.noise * rng.random(len(cost))))]
                if edge[0] == "transition" and self.shift[edge[1]]:
                    shifted.add(edge[1])
                    drifted += int(self.shift[edge[1]])
            edges.append(edge)
            state = self.step(state, edge)
        return self.path(start, edges)

    def _compiled(self) -> bool:
        """Whether the compiled loops (_kernels) walk this problem: with the tables (a graph that
        does not turn), in-step tables included where walks are avoided."""
        return self.compiled

    def _kernel_tables(self) -> tuple:
        step = self.step_table if self.step_table is not None else np.zeros((0, 0), dtype=bool)
        return np.ascontiguousarray(self.features), np.ascontiguousarray(self.track), step

    def _initial_compiled(self, rng, node) -> list:
        """The edges of initial's loop from `node`, by _kernels.initial: the same choices from
        the same random numbers (drawn here ahead, then the stream set to where initial leaves it)."""
        shared = self.shared
        state = np.array([node, 0, _kernels.NEVER, 0, 0, 0], dtype=np.int64)
        shifted = np.zeros(len(self.shift), dtype=bool)
        ints = np.array([self.needed, self.longest, self.n_clips, self.drift, self.ahead,
                         -1 if self.react is None else self.react, self.avoid is not None], dtype=np.int64)  # fmt: skip
        floats = np.array([self.alpha, self.dt, self.noise, self.vary, self.in_step], dtype=np.float64)
        saved = rng.bit_generator.state
        uniforms = rng.random(max(64, 2 * self.needed))
        kind = np.zeros(2 * self.needed + 16, dtype=np.int64)  # a clip plays a frame at least, a transition none
        index = np.zeros_like(kind)
        try:
            while True:
                status = _kernels.initial(state, shifted, uniforms, kind, index, shared.edge_kind, shared.edge_index,
                                          shared.edge_ahead, shared.edge_fixed, shared.n_edges, self.clip_frames,
                                          self.clip_target, self.trans_target, shared.shift_steps, self.straight,
                                          *self._kernel_tables(), ints, floats)  # fmt: skip
                if status == 0:
                    break
                if status == 2:
                    since = math.inf if state[2] >= _kernels.NEVER else int(state[2])
                    raise ValidationError(
                        f"annotated walk: node {int(state[0])} has no edge to take {since} frames after a transition"
                    )
                if state[4] + shared.edge_kind.shape[1] > len(uniforms):
                    uniforms = np.concatenate([uniforms, rng.random(len(uniforms))])
                if state[5] >= len(kind):
                    kind, index = np.concatenate([kind, kind]), np.concatenate([index, index])
        finally:  # the stream as initial leaves it: as many numbers drawn as it used
            rng.bit_generator.state = saved
            rng.random(int(state[4]))
        names = ("clip", "transition")
        return [(names[k], i) for k, i in zip(kind[: state[5]].tolist(), index[: state[5]].tolist())]

    def _start(self, rng) -> int:
        """A random node among those whose next two seconds stay within 0.1 (mean arrow error) of
        the best start; with walks to avoid, among those that play in step with them on the
        fewest of those frames (on a looping graph with phase shifts, of the whole walk, played
        straight on) and, with phase shifts, of those, come within 2 `drift` + 1 frames of them
        (where the drifts of both could bring them in step) on the fewest."""
        nodes = np.arange(len(self.nodes))
        frames = self.straight[nodes][:, : len(self.track)]
        played = self.features[frames]
        cost = np.linalg.norm(played - self.track[: frames.shape[1]], axis=2).sum(axis=1) / self.ahead
        if self.avoid is not None:
            frames_on = frames
            if self.period is not None and self.shift.any():
                # a drifting walk keeps within `drift` frames of going straight on: judge its whole length
                frames_on = (self.nodes[:, None] + np.arange(self.needed)) % self.period
            by_phase = frames_on is not frames and np.all(self.avoid[:, : self.needed] < self.period)
            for within in (1, 2 * self.drift + 1) if self.shift.any() else (1,):
                if by_phase:
                    near = self._in_step_by_phase(within)
                else:
                    near = self.in_step_frames(frames_on, 0, within).sum(axis=1)
                near = np.where(np.isfinite(cost), near, np.iinfo(np.int64).max)
                cost = np.where(near == near.min(), cost, np.inf)
        good = np.flatnonzero(cost <= cost.min() + 0.1)
        return int(rng.choice(good))

    def _in_step_by_phase(self, within: int) -> np.ndarray:
        """Per node, the output frames on which going straight on round the loop from it, from
        output frame 0, plays within `within` frames (around the loop) of an avoided walk: what
        ``in_step_frames((nodes + t) % period, 0, within).sum(axis=1)`` counts, counted by phase.
        Straight on from node n plays (n + t) % period at t, within of an avoided walk's frame o
        where n is within of the phase (o - t) % period; so each avoided frame marks the phases
        near its own, once per output frame, and each node counts the frames its phase is marked."""
        period = self.period
        others = self.avoid[:, : self.needed]
        valid = others >= 0
        times = np.broadcast_to(np.arange(self.needed), others.shape)[valid]
        phase = (others[valid] - times) % period
        marked = np.zeros((self.needed, period), dtype=bool)
        for step in range(-within, within + 1):
            marked[times, (phase + step) % period] = True
        return marked[:, self.nodes % period].sum(axis=0)

    def _monotony(self, edges, shifted, shift=None) -> np.ndarray | float:
        """`vary` on each of `edges` that takes a phase shift in `shifted` (taken before), and on
        going straight on where a phase shift not taken yet is among them; else 0 (going straight
        on plays a clip and finds other phase shifts at its end, where a blend taken again would
        replay all its frames). `shift`: which of `edges` are phase shifts, if known."""
        if shift is None:
            shift = np.array([kind == "transition" and bool(self.shift[i]) for kind, i in edges])
        if not shift.any():
            return 0.0
        taken = np.array([kind == "transition" and i in shifted for kind, i in edges])
        fresh = shift & ~taken
        return self.vary * (taken | (~shift & fresh.any()))

    def pick(self, path: _Path, rng, tried):
        """A stretch (first edge, edge after it) whose share of E per second exceeds the
        threshold, chosen with odds in proportion to the excess; None when there is none."""
        if path.stretches is None:  # the path's stretches and their excess, the same at each pick
            at = np.asarray(path.at[:-1])
            starts = np.flatnonzero(at < self.needed)
            stops = np.searchsorted(at, at[starts] + self.segment_frames)
            window = np.concatenate([[0.0], np.cumsum(path.error)])
            ends = np.minimum(at[starts] + self.segment_frames, self.needed)
            cost = self.alpha * self.dt * (window[ends] - window[at[starts]])
            running = path.running_cost
            cost += running[np.minimum(stops, len(path.edges))] - running[starts]
            rate = cost / (self.segment_frames * self.dt)
            path.stretches = starts, stops, np.where(rate > self.threshold, rate - self.threshold, 0.0)
        starts, stops, excess = path.stretches
        excess = excess.copy()
        for i, j in tried:  # starts are 0, 1, ...: stretch k starts at edge k
            if i < len(starts) and min(stops[i], len(path.edges)) == j:
                excess[i] = 0.0
        if not excess.any():
            return None
        # rng.choice(len(starts), p=excess / excess.sum()) as numpy makes it (the same draw and
        # index), without its checks of p
        cdf = np.cumsum(excess / excess.sum())
        cdf /= cdf[-1]
        k = int(cdf.searchsorted(rng.random(), side="right"))
        return int(starts[k]), int(min(stops[k], len(path.edges)))

    def replace(self, path: _Path, i: int, j: int) -> _Path | None:
        """The path with edges i..j-1 replaced by the best alternative between their ends, if it
        lowers E; None otherwise."""
        t0, old_frames = path.at[i], path.at[j] - path.at[i]
        tail = j == len(path.edges)
        goal = None if tail else path.node[j]
        slack = self.segment_frames // 2
        # frames after the join before the path's next transition: the join must leave room for its blend
        later = np.searchsorted(path.transitions_taken, j)
        lead = path.at[path.transitions_taken[later]] - path.at[j] if later < len(path.transitions_taken) else None
        old_cost = self.alpha * self.dt * path.error[t0:].sum() + path.running_cost[j] - path.running_cost[i]
        old_edges = path.edges[i:j]
        if self._compiled():
            since = path.since[i]
            ints = np.array([path.node[i], _kernels.NEVER if math.isinf(since) else int(since), t0, old_frames, tail,
                             -1 if tail else goal, slack, -1 if lead is None else lead, self.needed, self.longest,
                             self.MAX_TRANSITIONS, self.SEARCH_NODES, self.n_clips, self.period or 0,
                             self.avoid is not None], dtype=np.int64)  # fmt: skip
            floats = np.array([old_cost - 1e-9, self.alpha, self.dt, self.beta, self.in_step], dtype=np.float64)
            kinds = np.array([kind == "transition" for kind, _ in old_edges], dtype=np.int64)
            indices = np.array([index for _, index in old_edges], dtype=np.int64)
            suffix = np.ascontiguousarray(path.frames[path.at[j] :] if not tail else path.frames[:0], dtype=np.int64)
            size = self.SEARCH_NODES + 1  # each node expanded adds one edge at most
            best_kind, best_index = np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64)
            count = _kernels.replace(kinds, indices, suffix, self.shared.out_table, self.shared.out_count,
                                     self.trans_target, self.trans_cost, self.shared.shift_steps, self.clip_frames,
                                     self.clip_target, self.nodes, *self._kernel_tables(), ints, floats, best_kind,
                                     best_index)  # fmt: skip
            if count < 0:
                return None
            names = ("clip", "transition")
            best = [(names[k], i) for k, i in zip(best_kind[:count].tolist(), best_index[:count].tolist())]
            return self.path(path.start, [*path.edges[:i], *best, *path.edges[j:]])
        suffix = (path.played[path.at[j] :], path.frames[path.at[j] :]) if not tail else None
        best, best_cost = None, old_cost - 1e-9
        expanded = 0
        stack = [(path.node[i], path.since[i], path.rotation[i], 0, [], 0, 0.0)]
        while stack and expanded < self.SEARCH_NODES:
            node, since, rotation, frames, edges, n_trans, cost = stack.pop()
            expanded += 1
            done = (frames >= self.needed - t0) if tail else (node == goal and abs(frames - old_frames) <= slack)
            if done and edges != old_edges and (tail or lead is None or since + lead >= self.longest):
                total = cost + self._rest_cost(
                    path, t0 + frames, suffix, rotation @ path.rotation[j].T if not tail and self.rotating else None
                )
                if total < best_cost:
                    best, best_cost = edges, total
                if tail:
                    continue
            if frames > old_frames + slack:
                continue
            if since >= self.longest and n_trans < self.MAX_TRANSITIONS:
                for index in self.out[node]:
                    turned = rotation @ self.trans_rotation[index] if self.rotating else rotation
                    extra = self.trans_cost[index] + self.beta * (not self.shift[index])
                    stack.append(
                        (
                            self.trans_target[index],
                            0,
                            turned,
                            frames,
                            [*edges, ("transition", index)],
                            n_trans + 1,
                            cost + extra,
                        )  # fmt: skip
                    )
            if node < self.n_clips:
                n = self.clip_frames[node]
                error = self._clip_error(node, t0 + frames, rotation)
                stack.append(
                    (
                        int(self.clip_target[node]),
                        since + n,
                        rotation,
                        frames + n,
                        [*edges, ("clip", node)],
                        n_trans,
                        cost + self.alpha * self.dt * error,
                    )
                )
        if best is None:
            return None
        return self.path(path.start, [*path.edges[:i], *best, *path.edges[j:]])

    def _memo(self, t: int, n: int) -> tuple[dict, tuple]:
        """Where to remember an error over output frames t..t+n-1 (cut at the duration), and
        under what: the target arrow itself when it holds over the window and no walk is
        avoided (shared across walks), else the frame (this walk's)."""
        m = min(n, self.needed - t)
        if self.avoid is None and m > 0 and t + m - 1 <= self.run_end[t]:
            return self._per_run, (self.track[t].tobytes(), m)
        return self._per_walk, (t, m)

    def _clip_error(self, node: int, t: int, rotation) -> float:
        """frame_error summed over clip `node` played from output frame t, turned by `rotation`;
        remembered when the graph does not turn (searches meet the same clip under the same
        target again and again)."""
        if self.error_table is not None:  # the tables are as quick as the memo, and hold the same errors
            frames = self.wrap(self.nodes[node] + np.arange(max(min(self.clip_frames[node], self.needed - t), 0)))
            return float(self._table_error(frames, t).sum())
        memo, window = self._memo(t, self.clip_frames[node])
        key = ("clip", node, window)
        if not self.rotating and key in memo:
            return memo[key]
        n = self.clip_frames[node]
        frames = self.wrap(self.nodes[node] + np.arange(n))
        played = self.features[frames]
        if self.rotating:
            played = played @ rotation.T
        hi = min(t + n, self.needed)
        source = frames[: max(hi - t, 0)]
        error = float(self.frame_error(played[: len(source)], source, t).sum())
        if not self.rotating:
            memo[key] = error
        return error

    def _rest_cost(self, path, t, suffix, turn) -> float:
        """Constraint cost of the unchanged rest of the path played from output frame t (turned by
        `turn`); infinite if the path would then end before the duration."""
        if suffix is None:
            return 0.0
        played, frames = suffix
        if t + len(played) - 1 < self.needed:
            return math.inf
        n = max(self.needed - t, 0)
        played = played[:n] if turn is None else played[:n] @ turn.T
        return self.alpha * self.dt * float(self.frame_error(played, frames[:n], t).sum())
