"""Motion graphs of objects that stay in place (paper 002, section 4.3).

A flag, a plant or a part of a mesh is compared where it is: no rigid alignment, no reordering
(every transition's alignment is the identity). With d_x(p, q) and d_v(p, q) the mean over points
of the squared difference of positions, and of frame-to-frame displacements, between frames p and
q, the transition cost is

    D(p, q) = alpha * sum_{k=-n}^{n} d_x(p + k, q + k) + beta * sum_{k=-n}^{n} d_v(p + k, q + k)

over windows of 2n + 1 frames (`window` = n). Near the ends of the recording the window holds the
frames both sides have, its sum scaled up to 2n + 1 terms, so that a clip that loops finds the
transition from its last frame to its first. Means over points keep D independent of the mesh's
size; with alpha >= 1, D is at least the mean squared jump at the transition itself. All the
d_x and d_v are one matrix product each.

Transitions are the local minima of D at least `min_gap` seconds apart (pairs nearer than that are
neither candidates nor neighbors, so a motion that never comes back, such as a flock crossing the
scene, still has minima, at the edge of the gap; no blend hides those, see below). The threshold adapts as
kovar's does: the lowest local minima, until max(`min_transitions`, `transitions_per_minute` per
minute of recording) of them survive the trimming of dead ends (or all of them); `threshold`
makes it absolute instead. The adaptive rule takes only transitions that a blend can hide: the
largest distance between a point's places in the two motions over the blend (from p and q on)
must be at most (blend + 1) / 3 times the recording's largest step, so that the smoothstep blend
(whose steepest step moves 1.5 / (blend + 1) of that distance) adds at most half the largest
step to a point's own. If none is that good, the lowest minima are taken until one transition survives
(a recording with no good transition still gives a graph, the best it has). Minima whose costs
are equal but for rounding (a motion that repeats exactly, such as a steady flutter, has many)
are taken round-robin over the frames they leave from, spread across the recording, so that
transitions leave from all of it (every stretch of its features) rather than from wherever
rounding happened to be smallest; such a transition's distance is 0, not rounding noise.

Blend length (the paper compares D_pre, D_post and D without a rule; ours): with D_pre the mean of
the window's terms up to the transition and D_post the mean from it on, the blend is
`blend_time` when the two motions stay as close after the jump as before (D_post <= D_pre), and
shortened by D_pre / D_post when they grow apart, for a long blend would then mix increasingly
different poses; it is at least `min_blend` frames, and never runs past the end of the recording
(the old motion must exist to be blended), so a transition from the last frame is a cut.

A source that loops (``flockkit.graphs.loop_period``: a walk, run or flapping cycle whose first
frame follows its last) is compared around the loop: windows, velocities, the gap and blends
wrap, so transitions are found anywhere within the cycle, and the graph loops
(``MotionGraph.period``): a walk plays round the cycle along clips, with no cut back to its
first frame. Where the graph is too sparse to vary (fewer than `min_transitions` transitions a
blend can hide, as a short cycle, which has none, gives), phase shifts are added
(``flockkit.graphs.phase_shifts``): from every frame (at most SHIFT_NODES of them, evenly
spread), transitions to the frame 1 or 2 frames on and back, blended over `shift_blend` seconds,
so that walks start at any phase, drift in time and play out of step with each other. On a
cycle shorter than `shift_blend` the shifts blend over the cycle less one frame (a blend as long as
the cycle would mix a phase with itself one loop on), and only the sizes such a blend hides are
added (3 |shift| <= blend + 1: a 4-frame cycle gets shifts of one frame, a 2-frame cycle none).
"""

from __future__ import annotations

import itertools
import math

import attrs
import numpy as np

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

# Phase shifts of 1 and 2 frames each way (at most: their blend must hide them, 3 |shift| <=
# blend + 1). Our choice: with 0.6 s blends at 30 fps a 42-frame cycle gets 168 of them, so that a
# minute of drifting plays no blend twice, and the timing wavers by at most 16%.
SHIFT_SIZES = (1, 2)
# Frames that phase shifts leave from at most, evenly spread over the kept frames (our choice: a
# cycle of up to 128 frames gets them at every frame; longer sparse recordings, fewer).
SHIFT_NODES = 128
# Costs of minima this close, relative to the largest cost, are equal but for rounding (our
# choice: far above float64 rounding of the squared distances, far below any real difference).
TIE_TOLERANCE = 1e-9


@attrs.frozen(kw_only=True)
class Windowed:
    """Parameters
    ----------
    window : int
        n: windows of 2n + 1 frames.
    alpha, beta : float
        Weights of the position and velocity terms.
    min_gap : float
        Seconds at least between the two frames of a transition.
    threshold : float, optional
        Absolute threshold on D; None: adaptive (module docstring).
    min_transitions, transitions_per_minute : int, float
        What the adaptive threshold keeps.
    blend_time : float
        Longest blend, in seconds.
    min_blend : int
        Shortest blend, in frames.
    loops : bool
        Treat a source that loops (``flockkit.graphs.loop_period``) as a loop (module docstring).
    shift_blend : float
        Blend of the phase shifts added to a sparse graph, in seconds; 0: none.
    """

    window: int = validate.parameter("windowed", default=2, kind="integer", minimum=0)
    alpha: float = validate.parameter("windowed", default=1.0, minimum=0)
    beta: float = validate.parameter("windowed", default=1.0, minimum=0)
    min_gap: float = validate.parameter("windowed", default=0.3, minimum=0)
    threshold: float | None = validate.parameter("windowed", default=None, minimum=0, strict=True, optional=True)
    min_transitions: int = validate.parameter("windowed", default=10, kind="integer", minimum=1)
    transitions_per_minute: float = validate.parameter("windowed", default=60.0, minimum=0)
    blend_time: float = validate.parameter("windowed", default=0.3, minimum=0)
    min_blend: int = validate.parameter("windowed", default=2, kind="integer", minimum=0)
    loops: bool = validate.parameter("windowed", default=True, kind="flag")
    shift_blend: float = validate.parameter("windowed", default=0.6, minimum=0)

    def build(self, motion: flockkit.Motion, metric, rng: np.random.Generator) -> flockkit.MotionGraph:
        """The motion graph of `motion` (deterministic; the metric and `rng` are not used: the
        windowed cost compares points where they are)."""
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"windowed: motion must be a flockkit.Motion; got {type(motion).__name__}")
        frames = motion.n_frames
        if frames < 3:
            raise ValidationError(
                f"windowed: a motion of {frames} frames has no transition to find; it needs 3 or more"
            )
        period = flockkit.graphs.loop_period(motion) if self.loops else None
        total, pre, post = self.costs(motion, period=period)
        blends = self.blends(motion, pre, post, period=period)
        gap = max(1, math.ceil(self.min_gap / motion.dt - 1e-9))
        index = np.arange(len(total))
        apart = np.abs(index[:, None] - index[None, :])
        if period is not None:  # around the loop
            apart = np.minimum(apart, period - apart)
        far = apart >= gap
        # pairs nearer than min_gap are not candidates, nor neighbors that could hide one: a motion that
        # never returns (a flock crossing the scene) still has minima, along the edge of the gap
        rounding = _rounding(total)
        minima = _ordered(flockkit.graphs.local_minima(np.where(far, total, np.inf), far), total, rounding)
        shifting = self.shift_blend > 0 and round(self.shift_blend / motion.dt) >= 2
        if self.threshold is not None:
            chosen = [pq for pq in minima if total[pq] <= self.threshold]
        else:
            wanted = max(self.min_transitions, math.ceil(self.transitions_per_minute * motion.duration / 60))
            # a looping graph that gets phase shifts needs no poor transition to be walkable
            chosen = self._adaptive(motion, minima, total, blends, wanted, period, fallback=not (period and shifting))
        transitions = self._transitions(motion, chosen, total, blends, rounding)
        if shifting and self._kept(motion, chosen, blends, period) < self.min_transitions:
            transitions = self._with_shifts(motion, transitions, period)
        if not transitions:
            smallest = f"{total[minima[0]]:.4g}" if minima else "none"
            raise ValidationError(
                f"windowed: no transition under threshold {self.threshold}; the smallest cost of a local minimum is "
                f"{smallest}"
            )
        params = {
            "window": self.window,
            "alpha": self.alpha,
            "beta": self.beta,
            "min_gap": self.min_gap,
            "threshold": float(max(total[pq] for pq in chosen)) if chosen else None,
            "threshold_rule": "absolute" if self.threshold is not None else "adaptive",
            "blend_time": self.blend_time,
            "period": period,
            "shift_blend": self.shift_blend,
        }
        return flockkit.MotionGraph.assemble(motion, transitions, params=params, provenance={"builder": "windowed"},
                                             period=period)  # fmt: skip

    def costs(self, motion: flockkit.Motion, period: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(D, D_pre, D_post), each (T, T): D of the module docstring; D_pre and D_post the means of
        its terms over k <= 0 and k >= 0. With `period` (a looping source), each (period, period)
        over one cycle, the windows and velocities running on across the loop."""
        frames = motion.n_frames if period is None else period
        x = motion.positions[:frames].reshape(frames, -1)
        if period is None:
            steps = np.diff(x, axis=0)
            v = np.vstack([steps, steps[-1:]])  # the last frame keeps the last step
        else:
            v = np.roll(x, -1, axis=0) - x  # the last frame steps on to the first
        n_points = motion.n_agents
        terms = self.alpha * _squared_distances(x) / n_points + self.beta * _squared_distances(v) / n_points
        n = self.window
        sums = {side: np.zeros((frames, frames)) for side in ("pre", "post")}
        counts = {side: np.zeros((frames, frames)) for side in ("pre", "post")}
        for k in range(-n, n + 1):
            shifted, inside = _diagonal_shift(terms, k, wrap=period is not None)
            for side in ("pre",) * (k <= 0) + ("post",) * (k >= 0):
                sums[side] += shifted
                counts[side] += inside
        pre = sums["pre"] / np.maximum(counts["pre"], 1)
        post = sums["post"] / np.maximum(counts["post"], 1)
        count = counts["pre"] + counts["post"] - 1  # k = 0 is in both
        total = (sums["pre"] + sums["post"] - terms) * (2 * n + 1) / np.maximum(count, 1)
        return total, pre, post

    def _adaptive(self, motion, minima, total, blends, wanted, period=None, fallback=True):
        """The lowest minima a blend can hide (module docstring) until `wanted` transitions survive
        the trimming of dead ends; else (with `fallback`) the lowest until one does. Minima are
        looked at in order, only as far as needed (a part that never moves has a local minimum
        almost everywhere)."""
        x = motion.positions
        step = np.linalg.norm(np.diff(x, axis=0), axis=2).max()
        hidden = (pq for pq in minima if self._separation(x, *pq, int(blends[pq]), period) <= step * (1 + 1e-9))
        chosen, kept = [], 0
        while kept < wanted:
            more = list(itertools.islice(hidden, wanted - kept))
            if not more:
                break
            chosen += more
            kept = self._kept(motion, chosen, blends, period)
        if kept or not fallback:
            return chosen
        for count in range(1, len(minima) + 1):
            if self._kept(motion, minima[:count], blends, period):
                return minima[:count]
        return minima

    def _kept(self, motion, chosen, blends, period=None) -> int:
        """How many of the chosen transitions survive assembly (dead-end trimming)."""
        identity = flockkit.Alignment(distance=0.0, assignment=np.arange(motion.n_agents), rotation=np.eye(motion.dims),
                                      translation=np.zeros(motion.dims))  # fmt: skip
        return _surviving(motion, [(p, q, identity, int(blends[p, q])) for p, q in chosen], period)

    def _separation(self, x, p, q, blend: int, period=None) -> float:
        """The largest distance between a point's places in the two motions over the blend of
        p -> q (`blend` frames), times 3 / (blend + 1): at most the largest step for a blend to
        hide it."""
        if period is not None:  # both motions run on across the loop
            span = np.arange(max(blend, 1))
            apart = np.linalg.norm(x[(p + span) % period] - x[(q + span) % period], axis=2).max()
        else:
            span = min(max(blend, 1), len(x) - p, len(x) - q)  # the new motion may end first: then a jump
            apart = np.linalg.norm(x[p : p + span] - x[q : q + span], axis=2).max()
        return float(apart * 3 / (blend + 1))

    def _with_shifts(self, motion, transitions, period) -> list:
        """`transitions` and phase shifts for a sparse graph (module docstring): from up to
        SHIFT_NODES frames of the cycle, or of the frames the transitions span on a source that
        does not loop, each where a blend can hide it. There a walk must still reach the
        transitions' frames before the recording ends, so the shifts blend no longer than the
        longest of them, and are left out if the graph would keep fewer of them."""
        blend = max(self.min_blend, round(self.shift_blend / motion.dt))
        if period is not None:
            # at most one cycle less a frame: a longer blend would mix a phase with itself shifted
            # once more around the loop, and the graph holds no blend of n_frames or more
            blend = min(blend, period - 1, motion.n_frames - 1)
            first, last = 0, period - 1
        else:
            if not transitions:
                return transitions
            blend = min(blend, max(t[3] for t in transitions))
            frames = [f for p, q, _, _ in transitions for f in (p, q)]
            first, last = min(frames), max(frames)
        sizes = [s for size in SHIFT_SIZES if 3 * size <= blend + 1 for s in (size, -size)]
        if not sizes:
            return transitions
        frames = np.unique(np.linspace(first, last, min(SHIFT_NODES, last - first + 1)).round().astype(np.int64))
        x = motion.positions
        step = np.linalg.norm(np.diff(x, axis=0), axis=2).max()
        found = flockkit.graphs.phase_shifts(motion, frames, sizes=sizes, blend=blend, period=period)
        hidden = [t for t in found if self._separation(x, t[0], t[1], blend, period) <= step * (1 + 1e-9)]
        shifted = transitions + hidden
        if period is not None:
            return shifted
        try:
            graph = flockkit.MotionGraph.assemble(motion, shifted)
        except ValidationError:
            return transitions
        kept = len(graph.transitions) - int(np.count_nonzero(graph.shifts))
        return shifted if kept >= _surviving(motion, transitions) else transitions

    def blends(self, motion, pre, post, period: int | None = None) -> np.ndarray:
        """Blend frames of every transition p -> q, (T, T) (module docstring; with `period`, over
        one cycle, and not cut at the recording's end: the old motion runs on across the loop)."""
        longest = round(self.blend_time / motion.dt)
        ratio = np.minimum(1.0, (pre + 1e-300) / (post + 1e-300))
        blend = np.minimum(np.maximum(self.min_blend, np.round(longest * ratio)), max(longest, self.min_blend))
        if period is not None:
            return np.minimum(blend, motion.n_frames - 1).astype(np.int64)
        left = motion.n_frames - 1 - np.arange(motion.n_frames)  # frames after p: the old motion must exist
        return np.minimum(blend, left[:, None]).astype(np.int64)

    def _transitions(self, motion, chosen, total, blends, rounding):
        """The chosen (p, q) as transitions, their distance the cost D, or 0 where D is within
        `rounding` (``_rounding(total)``) of 0 (an exact repeat): walks weigh distances against their median, which
        rounding noise must not set."""
        found = []
        for p, q in sorted(chosen):
            blend = int(blends[p, q])
            distance = float(total[p, q]) if total[p, q] > rounding else 0.0
            identity = flockkit.Alignment(distance=distance, assignment=np.arange(motion.n_agents),
                                          rotation=np.eye(motion.dims), translation=np.zeros(motion.dims))  # fmt: skip
            found.append((p, q, identity, int(blend)))
        return found


def _ordered(minima, total, tolerance: float) -> list[tuple[int, int]]:
    """`minima` (p, q) by their cost total[p, q], lowest first. Costs equal but for rounding (within
    `tolerance`, ``_rounding(total)``: a motion that repeats exactly, as a steady flutter
    does, has many) are taken round-robin over their source frames p, the frames visited in an
    order spread evenly across the recording (bit-reversed), so that the transitions chosen first
    leave from all of it rather than from wherever rounding happened to be smallest; without
    that, a walk could hold only some of the recording's stretches (of its features)."""
    if not minima:
        return []
    pq = np.asarray(minima, dtype=np.int64)
    cost = total[pq[:, 0], pq[:, 1]]
    level = np.floor(cost / tolerance) if tolerance > 0 else cost
    rounds = np.zeros(len(pq), dtype=np.int64)  # how many cheaper (or tied, lower q) minima leave p before
    order = np.lexsort((pq[:, 1], cost, pq[:, 0]))
    p_sorted = pq[order, 0]
    starts = np.flatnonzero(np.r_[True, p_sorted[1:] != p_sorted[:-1]])
    rounds[order] = np.arange(len(pq)) - np.repeat(starts, np.diff(np.r_[starts, len(pq)]))
    spread = _bit_reversed(pq[:, 0])
    keys = np.lexsort((pq[:, 1], spread, rounds, level))
    return [minima[k] for k in keys]


def _rounding(total) -> float:
    """How far apart costs of `total` may be and still be equal but for rounding: TIE_TOLERANCE
    of the largest finite cost."""
    finite = total[np.isfinite(total)]
    return TIE_TOLERANCE * float(np.abs(finite).max()) if len(finite) else 0.0


def _bit_reversed(frames: np.ndarray) -> np.ndarray:
    """Each frame's bits reversed (over as many bits as the largest needs): an order that visits
    frames evenly spread, halving the spacing at each step (a van der Corput sequence)."""
    bits = max(1, int(frames.max()).bit_length())
    reversed_ = np.zeros_like(frames)
    for b in range(bits):
        reversed_ |= ((frames >> b) & 1) << (bits - 1 - b)
    return reversed_


def _surviving(motion, transitions, period=None) -> int:
    """How many of `transitions` survive MotionGraph.assemble (0 if it refuses them)."""
    if not transitions:
        return 0
    try:
        return len(flockkit.MotionGraph.assemble(motion, transitions, period=period).transitions)
    except ValidationError:
        return 0


def _squared_distances(rows: np.ndarray) -> np.ndarray:
    """|rows[p] - rows[q]|^2 for every p, q, by one matrix product."""
    norms = np.einsum("ij,ij->i", rows, rows)
    return np.maximum(norms[:, None] + norms[None, :] - 2 * rows @ rows.T, 0.0)


def _diagonal_shift(matrix: np.ndarray, k: int, wrap: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(matrix[p + k, q + k] where both exist else 0, 1 where they exist else 0); with `wrap`,
    indices run on around the matrix and always exist."""
    size = len(matrix)
    if wrap:
        return np.roll(matrix, (-k, -k), axis=(0, 1)), np.ones_like(matrix)
    shifted = np.zeros_like(matrix)
    inside = np.zeros_like(matrix)
    lo, hi = max(0, -k), min(size, size - k)
    shifted[lo:hi, lo:hi] = matrix[lo + k : hi + k, lo + k : hi + k]
    inside[lo:hi, lo:hi] = 1.0
    return shifted, inside
