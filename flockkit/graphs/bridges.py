"""Bridges: transitions a motion graph lacks, made by the constrained solver (papers 000 and 004).

A recording gives transitions only where its configurations recur, so a short or sparse one
leaves few, and a region walk may find no way to turn in time. :func:`bridge` makes the missing
ones: for a pair of source frames (a and b, each where a clip ends or starts), it solves a short
constrained flock (``flockkit.solve``) from a's configuration to b's, every agent
point-constrained at both ends (positions and velocity: two frames each), and adds it to the
graph as a clip with its two transitions, a -> bridge and bridge -> b.

How a graph holds the bridges. A graph's clips join consecutive nodes of one source motion, so
every clip must play continuous motion. The bridged graph's source is the recording followed by
one solved *chain*: it carries on from the recording's last frame, visits a copy of each bridged
frame in turn (a1, b1, a2, b2, ...; each copy is the frame's configuration moved rigidly to where
the flock has got to, its agents renumbered to the nearest slots), and ends with a short forward
simulation from the last visit, for the blends that leave it. Every visit is a node joined to its
frame by a transition each way; their alignments are the exact rigid motion and renumbering of
the copy, so their distance is 0. The stretch between two visits is a bridge from the first
visit's frame to the second's; those between pairs (b1 -> a2) and from the recording's end to the
first visit are bridges too, and the lead-in also keeps the recording's tail, which a builder's
trimming of dead ends drops. So the graph stays one MotionGraph (same invariants, same file
format, every walk unchanged) and stays strongly connected.

Placement. The copy of b faces the heading of the visit before it turned by the pair's `degrees`
(in 3D about the up axis), and its center of mass lies where the group gets to in `seconds` at
the mean of the two configurations' group speeds along a circular arc through that turn. Agents
are matched to slots by least squares (Hungarian) in configuration space (paper 000 section 4.1:
the center of mass at the origin, x along the heading), positions plus VELOCITY_WEIGHT times
velocities.

Plausibility. Each stretch is scored by the behavior's ``log_plausibility`` per agent-step (the
mean log density of its inferred wander impulses: a forward boids simulation scores about +0.66).
A stretch scoring below `min_plausibility`, or whose largest step exceeds STEP_LIMIT times the
recording's largest, is refused and its visit skipped: the chain carries on from the previous
visit to the next, so a refused pair costs only its own bridges. ``params["bridges"]`` of the
bridged graph lists every stretch tried (frames, turn, score, made or why not).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from .. import rigid
from ..constrained import PointConstraint, Problem, solve
from ..errors import FlockkitWarning, ValidationError
from ..motion import DEFAULT_UP, Alignment, Configuration, Motion, State
from ..registry import get, require_dims, resolve
from ..validate import integer, number
from ..validate import seed as validate_seed
from .graph import MotionGraph

__all__ = ["bridge", "bridge_plan", "BRIDGE_PLAUSIBILITY", "STEP_LIMIT"]

# The lowest log plausibility per agent-step a stretch may score. Measured on 20-boid recordings of
# 60 s (seeds 0, 8, 10, 14; 6 s stretches): a forward simulation scores about +0.67; the solver's
# straight stretches, which the recording itself could fill, -1.4 to -5; stretches turned 30
# degrees -11 to -34, 15 degrees over 4 s -8. For comparison, the graph's own transitions score
# about -41 over their 2 s blends and its rigid 15-degree turns -55 (from a walk's start, where
# plain clips score -0.9). So a bridge at the threshold is still more plausible than the
# transitions the builder made; lower it to keep more turns, raise it for fewer.
BRIDGE_PLAUSIBILITY = -20.0
# The largest step a stretch may take, as a multiple of the recording's largest step: under 1.5 (the
# synthesis quality bar), with room for the blends into and out of it.
STEP_LIMIT = 1.3
# Frames of motion before a stretch that its score reads (the model's inferred wander settles within
# a few frames of a motion's start: clips of a boids recording scored on their own lose 1.5 per
# agent-step over their first 2 s).
CONTEXT = 12
# Weight (s^2) of velocities in the matching of agents to a copy's slots (icp-hungarian's default).
VELOCITY_WEIGHT = 0.25


def bridge(
    graph: MotionGraph,
    pairs: Sequence,
    *,
    behavior,
    behavior_params: dict | None = None,
    seconds: float = 4.0,
    min_plausibility: float = BRIDGE_PLAUSIBILITY,
    transitions: Sequence = (),
    iterations: int = 0,
    refine: int = 40,
    seed: int | None = None,
) -> MotionGraph:
    """`graph` with solver-made bridges between the source frames of `pairs` (module docstring).

    Parameters
    ----------
    graph : MotionGraph
        A graph of a recording (not a looping one: its clips already go round its cycle).
    pairs : sequence of (a, b) or (a, b, degrees)
        Source frames of ``graph.motion`` to bridge from and to (a node's frame is where a clip
        ends and others start; any frame before the recording's last one will do, and one that
        is not a node becomes one), and the turn of the bridge in degrees (default 0).
    behavior : str or behavior model
        The model the bridges are solved and scored with (``flockkit.solve``'s `behavior`).
    behavior_params : dict, optional
        Its parameters, for a model made by name.
    seconds : float
        Duration of each bridge, at least the graph's longest blend (a walk takes no transition
        before a blend has played).
    min_plausibility : float
        Stretches whose log plausibility per agent-step is lower are refused.
    transitions : sequence of (start, end, alignment, blend)
        More transitions of the recording to assemble with (a builder's, that trimming dropped
        but bridges may now connect).
    iterations, refine : int
        Sampler iterations and least-squares steps per bridge (``flockkit.solve``). The
        least-squares steps make a bridge plausible; sampling after them changed no score measured
        (bench/README.md), so by default there is none.
    seed : int, optional
        Seeds every solve; the same seed gives the same graph.

    Returns
    -------
    MotionGraph
        Over the recording and the chain, with ``params["bridges"]`` describing every stretch
        tried and ``params["bridge_frames"]``, the first frame of the chain. With no stretch
        made, `graph` itself with that description.
    """
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"bridge needs a flockkit.MotionGraph; got {type(graph).__name__}")
    if graph.loops:
        raise ValidationError("bridge: a looping graph's clips already go round its cycle; bridges are for recordings")
    motion = graph.motion
    blend = int(graph.tables.transition_blend.max())
    seconds = number(seconds, "bridge: seconds", minimum=0, strict=True)
    length = round(seconds / motion.dt)
    if length < max(blend, 2):
        raise ValidationError(
            f"bridge: seconds must cover the graph's longest blend, {max(blend, 2) * motion.dt:g} s, so that a walk "
            f"can take the bridge's way out after its way in; got {seconds:g}"
        )
    min_plausibility = number(min_plausibility, "bridge: min_plausibility")
    iterations = integer(iterations, "bridge: iterations", minimum=0)
    refine = integer(refine, "bridge: refine", minimum=0)
    visits = _visits(pairs, motion.n_frames)
    model = _model(behavior, behavior_params, motion)
    chain = _Chain(motion, model, length, min_plausibility, (iterations, refine), validate_seed(seed))
    for frame, degrees in visits:
        if not chain.visit(frame, degrees) and degrees:
            chain.visit(frame, 0.0)  # turned too far to be plausible: straight on, so the chain goes on
    report = {"seconds": seconds, "min_plausibility": min_plausibility, "stretches": chain.report}
    if not chain.nodes:
        return MotionGraph(motion=motion, nodes=graph.nodes, clips=graph.clips, transitions=graph.transitions,
                           params={**graph.params, "bridges": report}, provenance=graph.provenance)  # fmt: skip
    extended = chain.motion(blend)
    kept = [(t.start, t.end, t.alignment, t.blend) for t in graph.transitions]
    extra = [_transition(t, motion.n_frames) for t in transitions]
    portals = [(s, e, a, blend) for s, e, a in chain.portals()]
    return MotionGraph.assemble(
        extended,
        kept + extra + portals,
        params={**graph.params, "bridges": report, "bridge_frames": motion.n_frames},
        provenance=graph.provenance,
    )


def bridge_plan(graph: MotionGraph, *, seconds: float = 6.0, degrees: float = 30.0) -> list[tuple[int, int, float]]:
    """Bridges where a graph of a recording needs them, as `pairs` for :func:`bridge`: a chain
    that plays the recording's own change of formation, `seconds` at a time, turning by `degrees`
    and -`degrees` in turn.

    The chain starts at the recording's end. Its first visit is `seconds` after the frame most
    like the end (least squares in configuration space, as the copies are matched), straight on;
    then every `seconds` to the recording's end, turned; then from the frame of its first `seconds`
    most like the last visit, on again, until the recording is covered once. So from
    its visits a walk may turn one way, from the next the other way, which a region walk needs
    where the recording turns too little; and the recording's dead ends, the head and tail that
    trimming drops with any small strongly connected components in them, join the graph."""
    if not isinstance(graph, MotionGraph):
        raise ValidationError(f"bridge_plan needs a flockkit.MotionGraph; got {type(graph).__name__}")
    seconds = number(seconds, "bridge_plan: seconds", minimum=0, strict=True)
    degrees = number(degrees, "bridge_plan: degrees", minimum=0, maximum=179)
    motion = graph.motion
    length = max(round(seconds / motion.dt), 1)
    last = motion.n_frames - 2  # a visit copies its frame and the next
    if last - length < 0:
        raise ValidationError(
            f"bridge_plan: a recording of {motion.n_frames} frames is too short for bridges of {seconds:g} s"
        )
    first = _most_like(motion, last, range(0, last - length + 1)) + length
    visits = list(range(first, last + 1, length))
    if first > 2 * length:  # the recording before the first visit, from its first `seconds`
        again = _most_like(motion, visits[-1], range(0, length)) + length
        visits += list(range(again, first - length + 1, length))
    pairs = []
    for k, (a, b) in enumerate(zip(visits, visits[1:])):
        straight = b != a + length  # the jump to a frame like the last visit
        pairs.append((a, b, 0.0 if straight else (degrees if k % 2 == 0 else -degrees)))
    return pairs or [(first, first, 0.0)]


def _most_like(motion: Motion, frame: int, candidates) -> int:
    """The candidate frame whose configuration is most like `frame`'s (agents matched)."""
    mine = _features(motion, frame)
    costs = []
    for other in candidates:
        cost = np.sum((mine[:, None] - _features(motion, other)[None]) ** 2, axis=-1)
        rows, cols = linear_sum_assignment(cost)
        costs.append(cost[rows, cols].sum())
    return int(list(candidates)[int(np.argmin(costs))])


def _features(motion: Motion, frame: int) -> np.ndarray:
    """Positions and VELOCITY_WEIGHT-weighted velocities of a frame in its configuration space."""
    x = motion.positions
    configuration = Configuration(positions=x[frame], velocities=(x[frame + 1] - x[frame]) / motion.dt)
    return _local(configuration)


def _local(configuration: Configuration) -> np.ndarray:
    axes = configuration.frame()
    velocities = math.sqrt(VELOCITY_WEIGHT) * axes.vectors_to_local(configuration.velocities)
    return np.hstack([axes.to_local(configuration.positions), velocities])


def _model(spec, params, motion: Motion):
    """The behavior model: made by name with the recording's dt, or the instance given, which must
    step that dt and handle its dimensions."""
    params = dict(params or {})
    if isinstance(spec, str):
        if "dt" in params:
            raise ValidationError("bridge: behavior_params dt comes from the graph's motion; leave it out")
        model = get("behavior", spec, dt=motion.dt, **params)
    else:
        model = resolve("behavior", spec, **params)
        step = getattr(model, "dt", motion.dt)
        if not math.isclose(step, motion.dt, rel_tol=1e-9):
            raise ValidationError(f"bridge: behavior steps dt = {step:g} s but the graph's motion has {motion.dt:g} s")
    require_dims("behavior", model, motion.dims, f"a {motion.dims}D graph", spec=spec)
    return model


def _visits(pairs, frames: int) -> list[tuple[int, float]]:
    """(frame, degrees of the stretch arriving there) for each frame the chain visits, in order:
    a1 (0), b1 (its pair's turn), a2 (0), ...; a frame repeating the one before visited once."""
    if isinstance(pairs, str | bytes):
        raise ValidationError("bridge: pairs must be a sequence of (a, b) or (a, b, degrees)")
    visits = []
    for index, pair in enumerate(pairs):
        try:
            items = tuple(pair)
        except TypeError:
            raise ValidationError(f"bridge: pairs[{index}] must be (a, b) or (a, b, degrees); got {pair!r}") from None
        if len(items) not in (2, 3):
            raise ValidationError(f"bridge: pairs[{index}] must be (a, b) or (a, b, degrees); got {pair!r}")
        a, b = (integer(f, f"bridge: pairs[{index}] frame", minimum=0) for f in items[:2])
        degrees = number(items[2], f"bridge: pairs[{index}] degrees") if len(items) == 3 else 0.0
        for frame in (a, b):
            if frame > frames - 2:
                raise ValidationError(
                    f"bridge: pairs[{index}] frame {frame} has no frame after it in the recording's {frames} frames "
                    "(a visit copies a frame and the next, for its velocity)"
                )
        if abs(degrees) >= 180:
            raise ValidationError(f"bridge: pairs[{index}] degrees must be within (-180, 180); got {degrees:g}")
        for frame, turn in ((a, 0.0), (b, degrees)):
            if not visits or visits[-1][0] != frame or turn:
                visits.append((frame, turn))
    if not visits:
        raise ValidationError("bridge: pairs is empty; give at least one (a, b)")
    return visits


def _transition(value, frames: int) -> tuple:
    try:
        start, end, alignment, blend = value
    except (TypeError, ValueError):
        raise ValidationError(
            f"bridge: transitions must be (start, end, alignment, blend) tuples; got {value!r}"
        ) from None
    if not isinstance(alignment, Alignment) or not (0 <= int(start) < frames and 0 <= int(end) < frames):
        raise ValidationError(f"bridge: transition {(start, end)} is not one of the recording's ({frames} frames)")
    return int(start), int(end), alignment, int(blend)


class _Chain:
    """The solved motion that follows the recording, visit by visit."""

    def __init__(self, motion: Motion, model, length, min_plausibility, effort, seed):
        self.source, self.model, self.length = motion, model, length
        self.min_plausibility, (self.iterations, self.refine) = min_plausibility, effort
        self.seeds = np.random.SeedSequence(seed)
        x = motion.positions
        self.largest_step = float(np.linalg.norm(np.diff(x, axis=0), axis=-1).max())
        self.recent = x[-CONTEXT:]  # the chain's last frames, which the score of the next stretch reads
        self.pieces = [x[-2:]]  # the frames the chain carries on from; the first two are the recording's
        self.offset = motion.n_frames - 2  # source frame of pieces' first row
        self.end = x[-2:]  # the chain's last two frames so far
        self.where = motion.n_frames - 1  # source frame that `end` copies, for the report (-1: a chain frame)
        # the recording frame the chain's end copies, and how: at first the recording's own end
        self.at = motion.n_frames - 2
        self.placement = (np.eye(motion.dims), np.zeros(motion.dims), np.arange(motion.n_agents))
        self.nodes: list[tuple[int, int, Alignment]] = []  # (chain frame, recording frame, copy's placement)
        self.report: list[dict] = []
        self.frames = motion.n_frames - 2  # source frame of self.end[0]

    def visit(self, frame: int, degrees: float) -> bool:
        """Solve the stretch from the chain's end to a copy of `frame`, turned by `degrees`; keep
        it if plausible. Whether it was kept."""
        target, alignment = self._copy(frame, degrees)
        entry = {"from": self.where, "to": frame, "degrees": degrees}
        problem = self._problem(target)
        rng_seed = int(self.seeds.spawn(1)[0].generate_state(1)[0])
        with warnings.catch_warnings():  # a bridge's reach is judged by its score, below
            warnings.simplefilter("ignore", FlockkitWarning)
            solution = solve(problem, behavior=self.model, iterations=self.iterations, refine=self.refine,
                             seed=rng_seed)  # fmt: skip
        # exact at both ends: the solver holds point constraints exactly; set them bit for bit
        positions = np.array(solution.motion.positions)
        positions[:2], positions[-2:] = self.end, target
        score = self._score(positions)
        step = float(np.linalg.norm(np.diff(positions, axis=0), axis=-1).max())
        entry.update(log_plausibility=score, step_ratio=step / self.largest_step)
        if score < self.min_plausibility:
            entry.update(made=False, why=f"log plausibility {score:.3g} per agent-step < {self.min_plausibility:g}")
        elif step > STEP_LIMIT * self.largest_step:
            ratio = step / self.largest_step
            entry.update(made=False, why=f"largest step {ratio:.3g} x the recording's > {STEP_LIMIT}")
        else:
            entry["made"] = True
            self.pieces.append(positions[2:])
            self.recent = np.concatenate([self.recent, positions[2:]])[-CONTEXT:]
            self.frames += self.length
            self.nodes.append((self.frames, frame, alignment))
            self.end, self.where = target, frame
            self.at, self.placement = frame, (alignment.rotation, alignment.translation, alignment.assignment)
        self.report.append(entry)
        return entry["made"]

    def _score(self, positions: np.ndarray) -> float:
        """Log plausibility per agent-step of a stretch's frames after its first (its impulses),
        read after the chain's frames before it: the model infers each impulse from the motion
        before it, which a stretch on its own lacks at its start."""
        before = self.recent[:-2]
        context = Motion(positions=np.concatenate([before, positions]), dt=self.source.dt)
        scored = self.model.log_plausibility(context, len(before) + 1, context.n_frames - 1)
        return float(np.sum(scored)) / (self.source.n_agents * (len(positions) - 2))

    def _copy(self, frame: int, degrees: float) -> tuple[np.ndarray, Alignment]:
        """Frames `frame` and `frame + 1` of the recording placed where the chain gets to in
        `length` frames, turned by `degrees`, agents in the chain's order; and the alignment
        ``copy = rotation @ recording[assignment] + translation``.

        Where the recording has the frame `length` before (its *lead*), the copy goes where the
        recording takes the group from there: the lead laid on the chain's end (exactly, where the
        end is a copy of the lead; else by their configuration frames, agents matched), then the
        whole turned about the end's center of mass, the way ahead by half the turn (a chord of an
        arc). Otherwise the copy faces the end's heading turned, a chord ahead at their mean group
        speed."""
        dt, d = self.source.dt, self.source.dims
        x = self.source.positions
        here = Configuration(positions=self.end[0], velocities=(self.end[1] - self.end[0]) / dt)
        lead = frame - self.length
        axis = None if d == 2 else DEFAULT_UP
        turn, half = rigid.rotation(math.radians(degrees), axis), rigid.rotation(math.radians(degrees) / 2, axis)
        center = here.center_of_mass()
        if lead >= 0 and lead == self.at:
            rotation, translation, assignment = self.placement
        else:
            reference = lead if lead >= 0 else frame
            there = Configuration(positions=x[reference], velocities=(x[reference + 1] - x[reference]) / dt)
            here_frame, there_frame = here.frame(), there.frame()
            rotation = here_frame.axes.T @ there_frame.axes
            translation = center - rotation @ there_frame.origin
            # agents to slots: least squares in configuration space, positions and velocities
            _, assignment = linear_sum_assignment(np.sum((_local(here)[:, None] - _local(there)[None]) ** 2, axis=-1))
            if lead < 0:  # no lead: a chord ahead at the mean group speed
                speed = np.linalg.norm(here.velocities.mean(axis=0)) + np.linalg.norm(there.velocities.mean(axis=0))
                translation = translation + speed / 2 * self.length * dt * here_frame.axes[0]
        # the turn: the way from the end's center to the copy's turned by half, the copy by all of it
        ahead = rigid.apply(rotation, translation, x[frame][assignment].mean(axis=0)) - center
        rotation = turn @ rotation
        translation = center + half @ ahead - rotation @ x[frame][assignment].mean(axis=0)
        copy = rigid.apply(rotation, translation, x[frame : frame + 2][:, assignment])
        return copy, Alignment(distance=0.0, assignment=assignment, rotation=rotation, translation=translation)

    def _problem(self, target: np.ndarray) -> Problem:
        """Every agent at the chain's end (frames 0 and 1) and at `target` (the last two frames)."""
        dt, n = self.source.dt, self.source.n_agents
        last = self.length  # the copy's frames: length and length + 1
        constraints = []
        for frames, at in (((0, 1), self.end), ((last, last + 1), target)):
            velocity = (at[1] - at[0]) / dt
            for k, frame in enumerate(frames):
                constraints += [PointConstraint(agent=i, time=frame * dt, position=at[k, i], velocity=velocity[i])
                                for i in range(n)]  # fmt: skip
        return Problem(n_agents=n, dims=self.source.dims, dt=dt, duration=(last + 1) * dt, constraints=constraints)

    def motion(self, blend: int) -> Motion:
        """The recording followed by the chain and `blend` + 1 frames simulated on from its last
        visit (the motion the blends leaving it fade out of)."""
        dt = self.source.dt
        state = State(positions=self.end[1], velocities=(self.end[1] - self.end[0]) / dt)
        rng = np.random.default_rng(self.seeds.spawn(1)[0])
        tail = self.model.forward(state, blend + 1, rng).positions[1:]
        chain = np.concatenate([*self.pieces[1:], tail], axis=0)
        return Motion(positions=np.concatenate([self.source.positions, chain], axis=0), dt=dt)

    def portals(self) -> list[tuple[int, int, Alignment]]:
        """(start, end, alignment) of each visit's transitions, to the chain and back."""
        found = []
        for at, frame, alignment in self.nodes:
            inverse_rotation, inverse_translation = rigid.invert(alignment.rotation, alignment.translation)
            back = Alignment(distance=0.0, assignment=np.argsort(alignment.assignment), rotation=inverse_rotation,
                             translation=inverse_translation)  # fmt: skip
            found += [(at, frame, alignment), (frame, at, back)]
        return found
