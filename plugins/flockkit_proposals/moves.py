"""Proposal moves of paper 004, section 3.4.1. Each returns a flockkit.constrained.Proposal (the new
motion and the frames and agents it changed) or None, never mutates the current motion, and never
moves an agent-frame the context pins: a point-constrained agent at a constrained frame, and (in
``flockkit.solve``) the starting state, frames 0 and 1 of every agent, which no term scores."""

from __future__ import annotations

import functools
import math

import attrs
import numpy as np
from scipy.interpolate import CubicSpline

import flockkit
from flockkit import validate
from flockkit.constrained import Proposal, regenerate


def _segment(context, n_frames, rng, short_probability):
    """A segment (first, last) of frames, maybe reaching past the motion: its length is 2 to 10
    steps with probability `short_probability`, else up to twice the motion; its centre is a frame
    drawn with probability inversely proportional to its plausibility exp(score)."""
    if rng.random() < short_probability:
        length = int(rng.integers(2, 11))
    else:
        length = int(rng.integers(11, max(12, 2 * n_frames + 1)))
    scores = np.asarray(context.scores, dtype=float)
    weights = np.exp(scores.min() - scores) if np.all(np.isfinite(scores)) else np.isneginf(scores).astype(float)
    centre = int(rng.choice(n_frames, p=weights / weights.sum()))
    first = centre - length // 2
    return first, first + length


def _quartic(u):
    return 16 * (u**2 - 2 * u**3 + u**4)


@attrs.frozen(kw_only=True)
class Bump:
    """Add 1 to `max_bumps` bumps d = 16 s (x^2 - 2x^3 + x^4), s ~ N(0, size x context.scale), each to one free
    agent's trajectory in multi-resolution coordinates, so that the bump follows the trajectory
    and scales with its sample spacing. A bump reaching past the motion is applied to the
    trajectory extended along its end velocities, and the part outside is dropped; one reaching
    before ``context.first_movable`` starts at the frame before it, so the held start stays."""

    size: float = validate.parameter("proposal", default=0.05, minimum=0, strict=True)
    max_bumps: int = validate.parameter("proposal", default=3, kind="integer", minimum=1)
    short_probability: float = validate.parameter("proposal", default=0.8, minimum=0, maximum=1)

    def propose(self, current, context, rng):
        positions = np.array(current.positions)
        n_frames = current.n_frames
        changed, low, high = set(), n_frames, -1
        for _ in range(int(rng.integers(1, self.max_bumps + 1))):
            first, last = _segment(context, n_frames, rng, self.short_probability)
            first = max(first, context.first_movable - 1)  # its zero end on the last held frame at most
            # frames the bump moves: all but its own (zero) ends, within the motion
            moved_first, moved_last = first + 1, min(last - 1, n_frames - 1)
            if moved_first > moved_last:
                continue
            free = context.free_agents(moved_first, moved_last + 1)
            if not len(free):
                continue
            agent = int(rng.choice(free))
            height = rng.normal(0.0, self.size * context.scale)
            new = _add_bump(_extended(positions[:, agent], first, last), height, rng)
            positions[moved_first : moved_last + 1, agent] = new[moved_first - first : moved_last - first + 1]
            changed.add(agent)
            low, high = min(low, moved_first), max(high, moved_last)
        if not changed:
            return None
        motion = flockkit.Motion(positions=positions, dt=current.dt, channels=dict(current.channels))
        return Proposal(motion=motion, start=low, stop=high + 1, agents=tuple(sorted(changed)))


@attrs.frozen(kw_only=True)
class Retime:
    """Re-time one free agent along its own path over a segment (chosen as for bumps, kept inside
    the motion): the arc length at each sample is offset by o = 16 s (u^2 - 2u^3 + u^4),
    s ~ N(0, spread * r * context.scale), r the segment's path length. Same path, same total distance, ends fixed
    (the first at ``context.first_movable - 1`` at the earliest); None when the offset would make the agent go
    backwards."""

    spread: float = validate.parameter("proposal", default=0.025, minimum=0, strict=True)
    short_probability: float = validate.parameter("proposal", default=0.8, minimum=0, maximum=1)

    def propose(self, current, context, rng):
        n_frames = current.n_frames
        first, last = _segment(context, n_frames, rng, self.short_probability)
        first, last = max(first, context.first_movable - 1, 0), min(last, n_frames - 1)
        if last - first < 2:
            return None
        free = context.free_agents(first + 1, last)
        if not len(free):
            return None
        agent = int(rng.choice(free))
        path = current.positions[first : last + 1, agent]
        travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        length = travelled[-1]
        if length <= 1e-12:
            return None
        u = np.linspace(0.0, 1.0, len(path))
        target = travelled + _quartic(u) * rng.normal(0.0, self.spread * length * context.scale)
        if np.any(np.diff(target) < 0):
            return None
        target[0], target[-1] = 0.0, length
        retimed = _along(path, travelled, target)
        positions = np.array(current.positions)
        positions[first + 1 : last, agent] = retimed[1:-1]
        motion = flockkit.Motion(positions=positions, dt=current.dt, channels=dict(current.channels))
        return Proposal(motion=motion, start=first + 1, stop=last, agents=(agent,))


def _along(path: np.ndarray, travelled: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The points of `path` (samples at arc lengths `travelled`) at arc lengths `target`, on the
    cubic spline through its samples: on the chords between samples, every retimed frame bent the
    path by up to a few tenths of a millimetre, which a model that reads impulses from third
    differences of positions (boids: about 900 x the offset) charges as a wander impulse."""
    if np.all(np.diff(travelled) > 0):
        return CubicSpline(travelled, path)(target)
    return np.stack([np.interp(target, travelled, path[:, k]) for k in range(path.shape[1])], axis=1)


@attrs.frozen(kw_only=True)
class Regenerate:
    """With probability `everything`, every window rebuilt as the initial trajectories build them,
    from the current starting state (frames 0 and 1, which ``flockkit.solve`` holds); otherwise 1
    to 3 contiguous windows rebuilt, held to the current motion at their ends (``regenerate``)."""

    everything: float = validate.parameter("proposal", default=0.5, minimum=0, maximum=1)

    def propose(self, current, context, rng):
        problem, behavior = context.problem, context.behavior
        everyone = tuple(range(current.n_agents))
        if rng.random() < self.everything:
            if current.n_frames < 3:
                return None
            motion = regenerate(problem, behavior, current, 0, current.n_frames - 1, rng)
            return Proposal(motion=motion, start=2, stop=current.n_frames, agents=everyone)
        spans = context.windows
        count = min(int(rng.integers(1, 4)), len(spans))
        first = int(rng.integers(0, len(spans) - count + 1))
        start, stop = spans[first][0], spans[first + count - 1][1]
        if stop - start < 2:
            return None
        motion = regenerate(problem, behavior, current, start, stop, rng)
        held = stop < current.n_frames - 1  # the last frame is free unless constrained
        return Proposal(motion=motion, start=start + 1, stop=stop if held else stop + 1, agents=everyone)


# -- multi-resolution bumps ---------------------------------------------------------------------


def _extended(track: np.ndarray, first: int, last: int) -> np.ndarray:
    """track's frames first..last, continued along its end velocities where they fall outside."""
    n = len(track)
    frames = np.arange(first, last + 1)
    inside = np.clip(frames, 0, n - 1)
    points = track[inside].copy()
    if n > 1:
        before, after = frames < 0, frames > n - 1
        points[before] = track[0] + frames[before, None] * (track[1] - track[0])
        points[after] = track[-1] + (frames[after, None] - (n - 1)) * (track[-1] - track[-2])
    return points


@functools.lru_cache(maxsize=512)
def _hierarchy(last: int) -> tuple:
    """(points, lefts, rights) per level, coarse to fine: each point with the neighbours it is
    coded against (the points of a level depend only on coarser ones). Cached: read only."""
    levels, spans = [], [(0, last)] if last >= 2 else []
    while spans:
        lefts, rights = np.array(spans).T
        middles = (lefts + rights) // 2
        levels.append(tuple(_read_only(a) for a in (middles, lefts, rights)))
        spans = [(a, b) for mid, left, right in zip(middles, lefts, rights) for a, b in ((left, mid), (mid, right))
                 if b - a >= 2]  # fmt: skip
    return tuple(levels)


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def _frames(spans: np.ndarray) -> np.ndarray:
    """Per span (M, D), rows: the unit vector along it and unit vectors across it (paper 004's n,
    s, t; in 3D the global r = z, or x where the span is along z), (M, D, D)."""
    length = np.linalg.norm(spans, axis=1, keepdims=True)
    along = np.where(length > 1e-12, spans / np.maximum(length, 1e-12), np.eye(spans.shape[1])[0])
    if spans.shape[1] == 2:
        return np.stack([along, np.column_stack([-along[:, 1], along[:, 0]])], axis=1)
    r = np.where(np.abs(along[:, 2:]) < 0.99, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    t = np.cross(r, along)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([along, np.cross(along, t), t], axis=1)


def _decompose(points: np.ndarray) -> list:
    """Per level of the hierarchy, each point's offset from its neighbours' midpoint in the frame
    of the span between them, over the span's length."""
    coefficients = []
    for middles, lefts, rights in _hierarchy(len(points) - 1):
        span = points[rights] - points[lefts]
        scale = np.maximum(np.linalg.norm(span, axis=1), 1e-12)[:, None]
        offset = points[middles] - (points[lefts] + points[rights]) / 2
        coefficients.append(np.einsum("mij,mj->mi", _frames(span), offset) / scale)
    return coefficients


def _recompose(ends: np.ndarray, coefficients: list, count: int) -> np.ndarray:
    points = np.empty((count, ends.shape[1]))
    points[0], points[-1] = ends
    for (middles, lefts, rights), level in zip(_hierarchy(count - 1), coefficients):
        span = points[rights] - points[lefts]
        scale = np.maximum(np.linalg.norm(span, axis=1), 1e-12)[:, None]
        points[middles] = (points[lefts] + points[rights]) / 2 + scale * np.einsum("mji,mj->mi", _frames(span), level)
    return points


def _add_bump(segment: np.ndarray, height: float, rng) -> np.ndarray:
    """The segment with a bump of `height` added in multi-resolution coordinates."""
    count, dims = segment.shape
    x = np.linspace(0.0, 1.0, count)
    bump = np.zeros((count, dims))
    bump[:, 0] = x
    across = _quartic(x) * height
    if dims == 2:
        bump[:, 1] = across
    else:
        angle = rng.uniform(0.0, 2 * math.pi)
        bump[:, 1], bump[:, 2] = across * math.cos(angle), across * math.sin(angle)
    mine, theirs = _decompose(segment), _decompose(bump)
    return _recompose(segment[[0, -1]], [m + t for m, t in zip(mine, theirs)], count)
