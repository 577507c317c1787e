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
(a recording with no good transition still gives a graph, the best it has).

Blend length (the paper compares D_pre, D_post and D without a rule; ours): with D_pre the mean of
the window's terms up to the transition and D_post the mean from it on, the blend is
`blend_time` when the two motions stay as close after the jump as before (D_post <= D_pre), and
shortened by D_pre / D_post when they grow apart, for a long blend would then mix increasingly
different poses; it is at least `min_blend` frames, and never runs past the end of the recording
(the old motion must exist to be blended), so a transition from the last frame is a cut.
"""

from __future__ import annotations

import itertools
import math

import attrs
import numpy as np

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError


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
        total, pre, post = self.costs(motion)
        blends = self.blends(motion, pre, post)
        gap = max(1, math.ceil(self.min_gap / motion.dt - 1e-9))
        index = np.arange(frames)
        far = np.abs(index[:, None] - index[None, :]) >= gap
        # pairs nearer than min_gap are not candidates, nor neighbors that could hide one: a motion that
        # never returns (a flock crossing the scene) still has minima, along the edge of the gap
        minima = sorted(flockkit.graphs.local_minima(np.where(far, total, np.inf), far), key=lambda pq: (total[pq], pq))
        if self.threshold is not None:
            chosen = [pq for pq in minima if total[pq] <= self.threshold]
        else:
            wanted = max(self.min_transitions, math.ceil(self.transitions_per_minute * motion.duration / 60))
            chosen = self._adaptive(motion, minima, total, blends, wanted)
        transitions = self._transitions(motion, chosen, total, blends)
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
        }
        return flockkit.MotionGraph.assemble(motion, transitions, params=params, provenance={"builder": "windowed"})

    def costs(self, motion: flockkit.Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(D, D_pre, D_post), each (T, T): D of the module docstring; D_pre and D_post the means of
        its terms over k <= 0 and k >= 0."""
        x = motion.positions.reshape(motion.n_frames, -1)
        steps = np.diff(x, axis=0)
        v = np.vstack([steps, steps[-1:]])  # the last frame keeps the last step
        n_points = motion.n_agents
        terms = self.alpha * _squared_distances(x) / n_points + self.beta * _squared_distances(v) / n_points
        frames, n = motion.n_frames, self.window
        sums = {side: np.zeros((frames, frames)) for side in ("pre", "post")}
        counts = {side: np.zeros((frames, frames)) for side in ("pre", "post")}
        for k in range(-n, n + 1):
            shifted, inside = _diagonal_shift(terms, k)
            for side in ("pre",) * (k <= 0) + ("post",) * (k >= 0):
                sums[side] += shifted
                counts[side] += inside
        pre = sums["pre"] / np.maximum(counts["pre"], 1)
        post = sums["post"] / np.maximum(counts["post"], 1)
        count = counts["pre"] + counts["post"] - 1  # k = 0 is in both
        total = (sums["pre"] + sums["post"] - terms) * (2 * n + 1) / np.maximum(count, 1)
        return total, pre, post

    def _adaptive(self, motion, minima, total, blends, wanted):
        """The lowest minima a blend can hide (module docstring) until `wanted` transitions survive
        the trimming of dead ends; else the lowest until one does. Minima are looked at in order,
        only as far as needed (a part that never moves has a local minimum almost everywhere)."""
        x = motion.positions
        step = np.linalg.norm(np.diff(x, axis=0), axis=2).max()
        hidden = (pq for pq in minima if self._separation(x, *pq, blends) <= step * (1 + 1e-9))
        chosen, kept = [], 0
        while kept < wanted:
            more = list(itertools.islice(hidden, wanted - kept))
            if not more:
                break
            chosen += more
            kept = self._kept(motion, chosen, blends)
        if kept:
            return chosen
        for count in range(1, len(minima) + 1):
            if self._kept(motion, minima[:count], blends):
                return minima[:count]
        return minima

    def _kept(self, motion, chosen, blends) -> int:
        """How many of the chosen transitions survive assembly (dead-end trimming)."""
        identity = flockkit.Alignment(distance=0.0, assignment=np.arange(motion.n_agents), rotation=np.eye(motion.dims),
                                      translation=np.zeros(motion.dims))  # fmt: skip
        transitions = [(p, q, identity, int(blends[p, q])) for p, q in chosen]
        try:
            return len(flockkit.MotionGraph.assemble(motion, transitions).transitions)
        except ValidationError:
            return 0

    def _separation(self, x, p, q, blends) -> float:
        """The largest distance between a point's places in the two motions over the blend of
        p -> q, times 3 / (blend + 1): at most the largest step for a blend to hide it."""
        blend = int(blends[p, q])
        span = min(max(blend, 1), len(x) - p, len(x) - q)  # the new motion may end first: then a jump
        apart = np.linalg.norm(x[p : p + span] - x[q : q + span], axis=2).max()
        return float(apart * 3 / (blend + 1))

    def blends(self, motion, pre, post) -> np.ndarray:
        """Blend frames of every transition p -> q, (T, T) (module docstring)."""
        longest = round(self.blend_time / motion.dt)
        ratio = np.minimum(1.0, (pre + 1e-300) / (post + 1e-300))
        blend = np.minimum(np.maximum(self.min_blend, np.round(longest * ratio)), max(longest, self.min_blend))
        left = motion.n_frames - 1 - np.arange(motion.n_frames)  # frames after p: the old motion must exist
        return np.minimum(blend, left[:, None]).astype(np.int64)

    def _transitions(self, motion, chosen, total, blends):
        found = []
        for p, q in sorted(chosen):
            blend = int(blends[p, q])
            identity = flockkit.Alignment(distance=float(total[p, q]), assignment=np.arange(motion.n_agents),
                                          rotation=np.eye(motion.dims), translation=np.zeros(motion.dims))  # fmt: skip
            found.append((p, q, identity, int(blend)))
        return found


def _squared_distances(rows: np.ndarray) -> np.ndarray:
    """|rows[p] - rows[q]|^2 for every p, q, by one matrix product."""
    norms = np.einsum("ij,ij->i", rows, rows)
    return np.maximum(norms[:, None] + norms[None, :] - 2 * rows @ rows.T, 0.0)


def _diagonal_shift(matrix: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(matrix[p + k, q + k] where both exist else 0, 1 where they exist else 0)."""
    size = len(matrix)
    shifted = np.zeros_like(matrix)
    inside = np.zeros_like(matrix)
    lo, hi = max(0, -k), min(size, size - k)
    shifted[lo:hi, lo:hi] = matrix[lo + k : hi + k, lo + k : hi + k]
    inside[lo:hi, lo:hi] = 1.0
    return shifted, inside
