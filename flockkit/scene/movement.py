"""Objects that move and turn (paper 002, section 5.2's self-movement constraints).

A template whose feature arrows are self-movement (``Features.speed`` set: a walk or a run played
in place, each frame's arrow its travel in its own coordinates) is not left where it is placed:
its heading follows the target arrow at its position (a flow field's, or the SelfMovement arrow
riding on it), turning at most `max_turn` radians a second, and it travels as far as the clip it
plays carries it.

The length of the target arrow asks for a speed: length x ``Features.speed``. Of the gaits the
template holds (its arrows grouped by length: a walk, a run), the one that reaches that speed at a
playback rate within RATES, nearest to 1, is played (the clip choice), at the rate that matches
it. The walk through the template's graphs follows that gait's arrow in source time, and the
object's clock (the source frame it plays at each output frame, a fraction between frames) runs
at the rate. Frame t moves the object by dt x rate x ``Features.speed`` x the arrow it plays,
turned by its heading: what the clip's feet push back in that time, so they do not slide.

``Paths`` is the result: per object and output frame, its position on the ground, its heading
about +z (unwrapped: it changes continuously) and its clock. Objects whose templates do not move
stand at their placement with clock t.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from .._arrays import readonly_float
from ..errors import ValidationError

__all__ = ["Paths", "Gaits", "MAX_TURN", "RATES"]

# The fastest an object turns by default: a quarter turn a second (our choice: a walking animal
# turns about that fast; Scene.max_turn sets it).
MAX_TURN = math.pi / 2
# Playback rates a clip is played at, lowest and highest (our choice: beyond them a walk looks
# slowed or hurried); a speed no gait reaches within them is reached as closely as they allow.
RATES = (0.25, 2.0)
# Arrows whose lengths differ by less than this are one gait.
GAIT_LENGTH = 0.02


@attrs.frozen(kw_only=True, eq=False)
class Paths:
    """Where each object of a scene is at each output frame: `positions` (M, F, 2) on the ground,
    `headings` (M, F) radians about +z (continuous, not wrapped), `clocks` (M, F) the source time,
    in frames, that each object plays at each output frame, and `moving` (M,) whether it moves."""

    positions: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Paths.positions"))
    headings: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Paths.headings"))
    clocks: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Paths.clocks"))
    moving: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=bool))

    def __attrs_post_init__(self):
        m, f = self.headings.shape
        if self.positions.shape != (m, f, 2) or self.clocks.shape != (m, f) or self.moving.shape != (m,):
            raise ValidationError(
                f"Paths: positions (M, F, 2), headings and clocks (M, F) and moving (M,) must agree; got "
                f"{self.positions.shape}, {self.headings.shape}, {self.clocks.shape}, {self.moving.shape}"
            )

    @property
    def rates(self) -> np.ndarray:
        """(M, F): the playback rate of each frame (clock[t + 1] - clock[t]; the last repeats)."""
        steps = np.diff(self.clocks, axis=1)
        return np.concatenate([steps, steps[:, -1:] if steps.shape[1] else np.ones((len(steps), 1))], axis=1)

    def __eq__(self, other):
        if not isinstance(other, Paths):
            return NotImplemented
        return all(np.array_equal(getattr(self, f), getattr(other, f)) for f in ("positions", "headings", "clocks",
                                                                                  "moving"))  # fmt: skip

    __hash__ = None


@attrs.frozen(eq=False)
class Gaits:
    """The gaits of a template whose arrows are self-movement: `lengths` (G,) increasing, the
    arrow each holds on average `arrows` (G, D), the template's `forward` (the angle of its mean
    arrow in the ground plane, in its own coordinates) and `speed` (``Features.speed``)."""

    lengths: np.ndarray
    arrows: np.ndarray
    forward: float
    speed: float

    @classmethod
    def of(cls, features) -> Gaits | None:
        """The gaits of `features`, None where they are forces (no speed)."""
        if features is None or features.speed is None:
            return None
        vectors = np.asarray(features.vectors)
        lengths = np.linalg.norm(vectors, axis=1)
        ground = vectors[:, :2].sum(axis=0)
        if np.linalg.norm(ground) < 1e-12:
            raise ValidationError(
                "self-movement features (Features.speed set) need arrows that point somewhere on the ground: "
                "their mean arrow has no x, y part"
            )
        group = np.round(lengths / GAIT_LENGTH).astype(np.int64)
        keys = np.unique(group)
        mean = np.array([lengths[group == k].mean() for k in keys])
        arrows = np.stack([vectors[group == k].mean(axis=0) for k in keys])
        return cls(lengths=mean, arrows=arrows, forward=float(np.arctan2(ground[1], ground[0])),
                   speed=float(features.speed))  # fmt: skip

    def choose(self, requested: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gait index, rate) for each of `requested` arrow lengths: the gait whose speed within
        RATES comes nearest, of those the rate nearest 1 (a gait of length 0, standing, plays at
        rate 1)."""
        requested = np.asarray(requested, dtype=float)
        positive = np.maximum(self.lengths, 1e-300)[None, :]
        rate = np.clip(requested[:, None] / positive, *RATES)
        rate = np.where(self.lengths[None, :] > 1e-9, rate, 1.0)
        reached = rate * self.lengths[None, :]
        miss = np.abs(reached - requested[:, None])
        cost = np.round(miss, 9) * 1e3 + np.abs(np.log(rate))  # the speed first, then the rate
        index = np.argmin(cost, axis=1)
        return index, rate[np.arange(len(index)), index]


def steer(start, headings, forward, *, n_frames: int, dt: float, max_turn: float, arrows_at, velocity):
    """Positions (F, M, 2) and headings (F, M) of objects starting at `start` (M, 2) turned by
    `headings` (M,), whose own forward is at angle `forward` (M,): at each frame t the target
    arrows w = arrows_at(positions, t) (M, >= 2, the world's), the object moves by dt x
    velocity(t, w, heading) (M, 2) and turns towards the heading that points its forward along
    w's ground part, by at most max_turn x dt (where w has no ground part, it keeps its heading).
    Also returns the targets (F, M, D)."""
    m = len(start)
    positions, turns = np.empty((n_frames, m, 2)), np.empty((n_frames, m))
    positions[0], turns[0] = start, headings
    targets = None
    step = max_turn * dt
    for t in range(n_frames):
        w = np.asarray(arrows_at(positions[t], t), dtype=float)
        if targets is None:
            targets = np.empty((n_frames, *w.shape))
        targets[t] = w
        if t + 1 == n_frames:
            break
        positions[t + 1] = positions[t] + dt * velocity(t, w, turns[t])
        ground = np.linalg.norm(w[:, :2], axis=1)
        desired = np.arctan2(w[:, 1], w[:, 0]) - forward
        error = (desired - turns[t] + np.pi) % (2 * np.pi) - np.pi
        turns[t + 1] = turns[t] + np.where(ground > 1e-9, np.clip(error, -step, step), 0.0)
    return positions, turns, targets


def travel(headings: np.ndarray, arrows: np.ndarray, rates: np.ndarray, speed: float) -> np.ndarray:
    """(M, 2): the world velocity of objects turned by `headings` (M,) playing `arrows` (M, D)
    (their own coordinates) at `rates` (M,): rate x speed x the arrow's ground part, turned."""
    c, s = np.cos(headings), np.sin(headings)
    x, y = arrows[:, 0], arrows[:, 1]
    return (rates * speed)[:, None] * np.column_stack([c * x - s * y, s * x + c * y])


def clocks_of(rates: np.ndarray) -> np.ndarray:
    """(..., F): the source time (frames) at each output frame of a clock running at `rates`."""
    return np.concatenate([np.zeros((*rates.shape[:-1], 1)), np.cumsum(rates[..., :-1], axis=-1)], axis=-1)


def at_clock(values: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """`values` (S, ...) per source frame read at fractional frames `clock` (F,): linear between
    the frames around each (the last frame held beyond it)."""
    last = len(values) - 1
    clock = np.clip(clock, 0, last)
    below = np.minimum(np.floor(clock).astype(np.int64), max(last - 1, 0))
    u = (clock - below).reshape(-1, *([1] * (values.ndim - 1)))
    above = np.minimum(below + 1, last)
    return (1 - u) * values[below] + u * values[above]


def source_track(gaits: Gaits, index: np.ndarray, clock: np.ndarray, dims: int) -> np.ndarray:
    """(S, dims): the arrow the walk follows at each source frame 0..ceil(clock[-1]) + 1: the gait
    chosen at the output frame whose clock has reached it."""
    frames = np.arange(int(math.ceil(clock[-1])) + 2)
    output = np.clip(np.searchsorted(clock, frames, side="right") - 1, 0, len(clock) - 1)
    return gaits.arrows[index[output]][:, :dims]


def source_frames_at(frames: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """(parts, F): the source frame each part plays at each output frame, from what it plays at
    each source-time frame (parts, S) and the clock (the nearest frame)."""
    index = np.clip(np.rint(clock).astype(np.int64), 0, frames.shape[1] - 1)
    return frames[:, index]


def avoid_in_source_time(avoid, clock: np.ndarray, n_source: int):
    """Other walks' source frames per output frame (K, F) as this walk's source-time frames see
    them (K, n_source): at source frame j, what they play at the output frame its clock reaches j."""
    if avoid is None:
        return None
    output = np.clip(np.searchsorted(clock, np.arange(n_source), side="right") - 1, 0, len(clock) - 1)
    return np.asarray(avoid)[..., output]


@attrs.frozen(eq=False)
class Course:
    """A moving object's plan: the arrow its walk follows at each source frame, `track` (S, D),
    and its `clock` (F,): the source time it plays at each output frame."""

    track: np.ndarray
    clock: np.ndarray

    @property
    def n_source(self) -> int:
        return len(self.track)


def _by_template(gaits: list) -> list[tuple[Gaits, np.ndarray]]:
    """(gaits, rows) for each distinct Gaits among `gaits` (one per moving object)."""
    groups = {}
    for row, g in enumerate(gaits):
        groups.setdefault(id(g), (g, []))[1].append(row)
    return [(g, np.array(rows)) for g, rows in groups.values()]


def plan(gaits: list, start, headings, *, n_frames: int, dt: float, max_turn: float, arrows_at, dims: list):
    """Courses of moving objects: `gaits` (one Gaits per object), `start` (M, 2), `headings`
    (M,), `arrows_at(positions (M, 2), t)` their target arrows; `dims` each template's source
    dimensions. Each frame the length of the ground part of the target asks for a speed, a gait
    and a rate are chosen (Gaits.choose) and the object steers and moves as that gait carries it.
    Returns (courses, rates (M, F))."""
    groups = _by_template(gaits)
    rates = np.ones((len(gaits), n_frames))
    chosen = np.zeros((len(gaits), n_frames), dtype=np.int64)
    forward = np.array([g.forward for g in gaits])

    def velocity(t, w, turned):
        out = np.empty((len(w), 2))
        for g, rows in groups:
            index, rate = g.choose(np.linalg.norm(w[rows, :2], axis=1))
            chosen[rows, t], rates[rows, t] = index, rate
            out[rows] = travel(turned[rows], g.arrows[index], rate, g.speed)
        return out

    _, _, targets = steer(start, headings, forward, n_frames=n_frames, dt=dt, max_turn=max_turn,
                          arrows_at=arrows_at, velocity=velocity)  # fmt: skip
    velocity(n_frames - 1, targets[-1], np.zeros(len(gaits)))  # the last frame's gait and rate
    courses = []
    for row, g in enumerate(gaits):
        clock = clocks_of(rates[row])
        courses.append(Course(track=source_track(g, chosen[row], clock, dims[row]), clock=clock))
    return courses, rates


def settle(gaits: list, played: list, rates, start, headings, *, dt: float, max_turn: float, arrows_at):
    """Positions (M, F, 2) and headings (M, F) of moving objects as their walks carry them:
    `played` (one (S, D) array per object) the arrows each plays per source frame, `rates` (M, F)
    its clock's rates; each frame moves it by dt x rate x speed x the arrow played at its clock,
    turned by its heading, which follows the targets as in :func:`plan`."""
    rates = np.asarray(rates)
    n_frames = rates.shape[1]
    clocks = clocks_of(rates)
    arrows = np.stack([at_clock(a[:, :2], c) for a, c in zip(played, clocks)], axis=1)  # (F, M, 2)
    speed = np.array([g.speed for g in gaits])
    forward = np.array([g.forward for g in gaits])

    def velocity(t, w, turned):
        return travel(turned, arrows[t], rates[:, t], 1.0) * speed[:, None]

    positions, turns, _ = steer(start, headings, forward, n_frames=n_frames, dt=dt, max_turn=max_turn,
                                arrows_at=arrows_at, velocity=velocity)  # fmt: skip
    return positions.transpose(1, 0, 2), turns.T
