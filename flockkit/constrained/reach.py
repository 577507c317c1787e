"""What the model's agents do unconstrained, and the constraints that ask for more.

``solve`` simulates a random flock of the problem's size with the behavior model, unconstrained and
out of reach of the problem's obstacles, and reads two things from it:

- the model's speeds (the 10th, 90th and 99th percentiles of every agent's speed), which aim the
  COM tracks (``com_aims``) and judge each constraint's speed, given or implied by the constraint
  before it on the same agent or subset;
- how fast the model's agents, or its groups of a track's size, turn: for three consecutive
  constraints of a track at t0 < t1 < t2, the two legs' mean velocities differ by
  |dv| = |(p2 - p1) / (t2 - t1) - (p1 - p0) / (t1 - t0)|, and somewhere within [t0, t2] the agent
  (or the group's center) must accelerate by at least |dv| / (t2 - t0) on average. The same figure,
  measured on the simulation over every window of the same legs, says what the model does.

Shapes hold each of their agents somewhere inside them, so for two constraints that hold an agent
one after the other, one of them a shape, the speed judged is the gap between their bounding boxes
over the time between them: a bound that never overstates. Three or more shapes that hold the same
agents one after the other also make a track of their centroids, whose turns are judged as a COM
track's are: the initial trajectories fill each shape with samples uniform in it, so the group's
center is there up to the samples' scatter. Overlapping shapes ask for no speed by their boxes'
gap, yet may turn their group far harder than the model's groups turn (paper 004's arrows,
pointing right, up and left 4 s apart, turned the center of their 50 agents at 0.19 length units
per second squared, where boids groups of 50 turn at up to 0.03).

A constraint asking for more than IMPLAUSIBLE (speed) or IMPLAUSIBLE_TURN (turn) times the
model's 99th percentile gets a FlockkitWarning naming it and both figures: the solve still meets
it, with its agents moving as the model's would not. (Of the shipped examples only beyond-reach
warns: its runner must average 1.92 length units per second where boids move at up to about 1.15.
Looping-3d's loop at the default speed and in 9 s turned its group at up to 0.29, 6-9 times what
the model's groups do; the shipped loop takes 18 s, its flock cruising at 0.5.)
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import FlockkitWarning
from ..motion import Motion, State, random_flock
from .problem import ComConstraint, Problem, ShapeConstraint

# A constraint asking for more than this many times the model's 99th percentile of speed, or of a
# track's turn, is one no model-like motion meets. Turns are told apart less sharply: one-agent's
# S at half its height (about 1.6 times the 99th percentile) is met as the model moves, the S
# itself (about 3 times) costs its agent dearly even alone (bench/README.md).
IMPLAUSIBLE = 1.5
IMPLAUSIBLE_TURN = 2.5
# Steps a random flock takes to gather (3 s at 10 Hz) before it is measured, and the steps whose
# speeds are read: a flock's own speed wanders for seconds (the median of 60 steps' second half
# was 0.93-1.07 for boids that cruise at 1.0).
WARM_UP = 50
MEASURED = 100
# Windows of a turn read: fewer let the 99th percentile wander with the seed (one-agent's S, seeds
# 1-10: 2.6-3.8 times it from 500 windows, 2.9-3.5 from 1 500, which take 0.1 s to simulate).
TURN_WINDOWS = 1500
# Length units per second no unconstrained agent exceeds: ten times the speed of a random flock,
# the scale every measure here assumes.
OPEN_SPEED = 10.0


def unconstrained(problem: Problem, model, seed) -> Motion:
    """A random flock of the problem's size simulated by `model` for WARM_UP + MEASURED steps, and,
    where the problem's tracks turn (three consecutive constraints), on for TURN_WINDOWS windows of
    the longest turn; in open space, out of reach of the problem's obstacles (see ``_open_space``)."""
    rng = np.random.default_rng(seed)
    steps = WARM_UP + MEASURED
    longest = max((sum(legs) for *_, legs in _turns(problem)), default=None)
    more = 0 if longest is None else WARM_UP + longest + TURN_WINDOWS - steps
    flock = _open_space(problem, random_flock(n_agents=problem.n_agents, dims=problem.dims, rng=rng), steps + more)
    motion = model.forward(flock, steps, rng)
    if more > 0:
        tail = model.forward(motion.state(-1), more, rng)
        motion = Motion(positions=np.concatenate([motion.positions, tail.positions[1:]]), dt=motion.dt)
    return motion


def _open_space(problem: Problem, flock: State, steps: int) -> State:
    """`flock` moved beyond the problem's obstacles by more than it can travel in `steps`: the model
    (made with the problem's obstacles) avoids them, and a flock started among them would measure
    the speeds of its avoidance, faster than the model's cruise, and aim the COM tracks too fast."""
    if not problem.obstacles:
        return flock
    corner = np.max([obstacle.bounds()[1] for obstacle in problem.obstacles], axis=0)
    travel = OPEN_SPEED * steps * problem.dt + np.max(np.abs(flock.positions))
    return State(positions=flock.positions + corner + travel, velocities=flock.velocities)


def speeds(free: Motion) -> np.ndarray:
    """Every agent's speed over the MEASURED steps after the warm-up."""
    measured = Motion(positions=free.positions[: WARM_UP + MEASURED + 1], dt=free.dt)
    return np.linalg.norm(measured.velocities()[WARM_UP:], axis=-1).ravel()


def warn_beyond(problem: Problem, free: Motion, fastest: float) -> None:
    """Warn (FlockkitWarning) about each constraint whose speed (given, or implied by the one
    before it on the same agent or subset, or by the gap to a shape, see ``_shape_legs``) is above
    IMPLAUSIBLE x `fastest`, and each whose track turns there harder than IMPLAUSIBLE_TURN x what
    `free`'s agents (or groups of the track's size) do."""
    index = {id(c): k for k, c in enumerate(problem.constraints)}
    unlike = (f"the model's agents move at up to {fastest:.3g} unconstrained, so the solution meets it with motion "
              "that does not look like the model's")  # fmt: skip

    def warn(constraint, text):
        where = f"constraint {index[id(constraint)]} ({type(constraint).__name__} at t={constraint.time:g})"
        warnings.warn(f"{where} {text}", FlockkitWarning, stacklevel=4)

    for track in problem.tracks:
        for before, after in zip(track[:-1], track[1:]):
            speed = np.linalg.norm(np.asarray(after.position) - before.position) / max(after.time - before.time, 1e-12)
            if speed > IMPLAUSIBLE * fastest:
                warn(after, f"is {speed:.3g} length units per second from constraint {index[id(before)]} at "
                            f"t={before.time:g}; {unlike}")  # fmt: skip
        for c in track[:1] if len(track) == 1 else ():  # a lone constraint's speed is its given velocity
            speed = float(np.linalg.norm(c.velocity))
            if speed > IMPLAUSIBLE * fastest:
                warn(
                    c, f"asks for a speed of {speed:.3g}; the model's agents move at up to {fastest:.3g} unconstrained"
                )
    for before, after, gap in _shape_legs(problem):
        speed = gap / (after.time - before.time)
        if speed > IMPLAUSIBLE * fastest:
            warn(after, f"is at least {gap:.3g} length units from constraint {index[id(before)]} at t={before.time:g} "
                        f"(the gap between their bounding boxes), so its agents move at {speed:.3g} length units per "
                        f"second at least; {unlike}")  # fmt: skip
    for (first, middle, last), needed, legs in _turns(problem):
        group = problem.agents_of(middle)
        usual = np.percentile(_turning(free, group, legs), 99)
        if needed > IMPLAUSIBLE_TURN * usual:
            who = "its agent" if len(group) == 1 else f"its {len(group)} agents' center"
            peers = "agents" if len(group) == 1 else f"groups of {len(group)}"
            movers = "its agent" if len(group) == 1 else "its agents"
            warn(middle, f"turns {who} at {needed:.3g} length units per second squared on average between "
                         f"t={first.time:g} and t={last.time:g} (the change of its legs' mean velocities over "
                         f"{last.time - first.time:g} s); unconstrained, the model's {peers} turn at up to "
                         f"{usual:.3g} over as long, so the solution meets it with {movers} moving as the "
                         "model's would not")  # fmt: skip


def shapes_apart(problem: Problem) -> bool:
    """Whether some shape constraint lies apart from a place that holds its agents before or after
    it, or turns a track of shapes (``_shape_tracks``), so that ``warn_beyond`` has its speed or
    turn to judge."""
    return bool(_shape_tracks(problem)) or any(gap > 0 for *_, gap in _shape_legs(problem))


def _shape_tracks(problem: Problem) -> list:
    """Shape constraints holding the same agents, three or more (a turn), each group in time order:
    tracks whose turns are judged by their centroids (see ``_place``)."""
    groups: dict = {}
    for constraint in problem.constraints:
        if isinstance(constraint, ShapeConstraint):
            groups.setdefault(tuple(problem.agents_of(constraint)), []).append(constraint)
    return [sorted(group, key=lambda c: c.time) for group in groups.values() if len(group) >= 3]


def _place(constraint) -> np.ndarray:
    """Where a constraint holds its agent or group's center: its position, or a shape's centroid."""
    if isinstance(constraint, ShapeConstraint):
        return np.asarray(constraint.shape.centroid(), dtype=float)
    return np.asarray(constraint.position, dtype=float)


def _shape_legs(problem: Problem):
    """Per pair of constraints that hold an agent one after the other, at least one of them a
    shape: the two and how far apart their places are at least (the gap between their bounding
    boxes, a point's box being the point: it never overstates, and is exact for boxes). COM
    constraints hold a group's center, not its agents, and are left to the tracks."""
    held: dict = {}
    for constraint in problem.constraints:
        if not isinstance(constraint, ComConstraint):
            for agent in problem.agents_of(constraint):
                held.setdefault(agent, []).append(constraint)
    pairs = {}
    for constraints in held.values():
        ordered = sorted(constraints, key=lambda c: c.time)
        for before, after in zip(ordered, ordered[1:]):
            if after.time > before.time and any(isinstance(c, ShapeConstraint) for c in (before, after)):
                pairs[id(before), id(after)] = before, after
    for before, after in pairs.values():
        (low, high), (other_low, other_high) = _box(before), _box(after)
        yield before, after, float(np.linalg.norm(np.maximum(0.0, np.maximum(other_low - high, low - other_high))))


def _box(constraint) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(constraint, ShapeConstraint):
        return constraint.shape.bounds()
    return np.asarray(constraint.position), np.asarray(constraint.position)


def _turns(problem: Problem):
    """Per three consecutive constraints of a track: the three, the acceleration they ask for on
    average (less what COM constraints may miss by, 3 sigma_com at each), and the two legs' frames."""
    for track in list(problem.tracks) + _shape_tracks(problem):
        for first, middle, last in zip(track, track[1:], track[2:]):
            legs = (problem.frame(middle.time) - problem.frame(first.time),
                    problem.frame(last.time) - problem.frame(middle.time))  # fmt: skip
            if min(legs) < 1:
                continue
            a, b = (leg * problem.dt for leg in legs)
            slack = 2 * 3 * problem.sigma_com * (1 / a + 1 / b) if isinstance(middle, ComConstraint) else 0.0
            rate = _turn_rate(_place(first), _place(middle), _place(last), a, b, slack)
            yield (first, middle, last), float(rate), legs


def _turning(free: Motion, group, legs) -> np.ndarray:
    """The `_turns` figure over every window of `legs` frames after the warm-up, for each agent
    of `free` (a group of one) or the center of its first len(group) agents."""
    positions = free.positions[WARM_UP:]
    centers = positions if len(group) == 1 else positions[:, : len(group)].mean(axis=1, keepdims=True)
    a, b = legs
    count = len(centers) - a - b
    first, middle, last = centers[:count], centers[a : a + count], centers[a + b : a + b + count]
    return _turn_rate(first, middle, last, a * free.dt, b * free.dt).ravel()


def _turn_rate(first, middle, last, a, b, slack=0.0):
    """How fast the mean velocity turns from the leg first -> middle (`a` seconds) to middle ->
    last (`b` seconds): the change of the two, less `slack`, over a + b seconds."""
    change = np.linalg.norm((last - middle) / b - (middle - first) / a, axis=-1)
    return np.maximum(0.0, change - slack) / (a + b)
