"""Initial trajectories that meet every constraint exactly (paper 004, section 3.3).

The frames before the first constrained frame are simulated backward from the configuration
there. When only point and COM constraints sit there (points for a model declaring ``guide``),
they are simulated again forward from the backward simulation's first frame: the
point-constrained agents kept on their backward paths, the simulation kept of several whose COM
groups head best for their paths' next constraints, each group then translated onto its center
(one translation for the whole lead-in, which leaves the group's own motion as simulated). A
backward simulation is not forward-plausible (its residuals are tens of times a free flock's; a
forward lead-in's are a free flock's, bench/README.md). Then, window by window (see ``windows``):

1. simulate forward from the window's start state (Operation 1). A model that declares
   ``Capabilities(guide=True)`` simulates with the agents of spanning point sequences already on
   their B-spline paths, so the others react to where they really are. The groups of spanning COM
   sequences reach their constraint frames by the model's own draws: every few frames the
   simulation is drawn several times and the draw heading best for the next constraint kept
   (``_Initial._reach``); nothing is added to any agent's impulses. The simulation starts one
   frame early, so that windows join without a step that has no impulse;
2. move the agents of point and COM sequences that span the window onto their B-spline paths,
   and every other agent by the translation of the nearest such agent at the window start, or of
   the COM path (Operation 2; a guided agent needs no move, and neither do those following it).
   A group is moved onto its path only at the window's ends and at its constraints' frames, the
   moves joined by a clamped cubic: moved at every frame, it would lose the wander of its own
   agents, which each agent then pays for as an impulse at every frame (on a 14 s race the free
   agents' median impulse was 0.21 moved at every frame, against 0.084 for a free flock). The
   draws leave these moves a few centimetres at most: a move along the path changes the group's
   speed, which the model's speed rule pushes back against at every frame of the move;
3. if constraints at the window end are still unmet, build a constrained end configuration from
   the forward result (section 3.3.1), simulate backward from it, path-transform that as well, and
   blend the two with u = 3t^2 - 2t^3; without a spanning sequence, the COM is moved along a
   Hermite curve between the window's end states (Operation 3).

Agents are then kept ``Problem.clearance`` out of the problem's obstacles (constrained
configurations too), each COM constraint still met exactly.

Constrained configurations (section 3.3.1) start from a snapshot. Point-constrained agents are
moved rigidly onto their position with their velocity; a COM subset is moved rigidly so that its
COM and mean velocity match; a shape subset gets uniform samples in the shape, relaxed apart. At a
window end, agents are re-assigned among the subset's slots by a sampled matching that keeps
their travel from the window start short. Unconstrained agents take the rigid transform of the
nearest (or, with ``Problem.follow = "random"``, a random) constrained agent in the snapshot.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicHermiteSpline, CubicSpline
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import linear_sum_assignment

from .. import rigid
from ..interfaces import capabilities
from ..motion import Motion, State, random_flock
from .problem import ComConstraint, PointConstraint, Problem, ShapeConstraint, track_path
from .windows import windows

# Steps of unconstrained simulation behind a snapshot: 3 s at the paper's 10 Hz, long enough for
# a random flock to gather (paper 004, 3.3.1 starts from "a snapshot of an unconstrained flock").
_WARM_UP = 30
# Relaxation steps pushing shape samples apart; 5 steps of a quarter of the overlap each (our
# choice) take the closest pairs to about 0.7 of the mean spacing.
_RELAXATION_STEPS = 5
# Agents pushed out of obstacles: pushes spread over a Gaussian of this many seconds, _PUSHES times
# (our choice: spreads from 0.3 to 0.8 s gave solves within one another's spread, and far better
# than none; bench/README.md).
_SPREAD = 0.5
_PUSHES = 4
# Reaching COM constraints by the model's own draws (_Initial._reach; our choices, on
# come-from-behind, seeds 1-12, bench/README.md): _ROLLOUTS simulations from every checkpoint,
# _CHECKPOINT frames apart, judged with _PILOTS simulations to the constraint frame; a stretch
# drawn again up to _ATTEMPTS times while it ends farther than _TOLERANCE sigma_com away. A
# proposal's draw (regenerate, accepted 1-2% of the time) takes _LIGHT simulations every
# _LIGHT_CHECKPOINT frames, unjudged and once: the thorough draw made solves ten times as long.
_ROLLOUTS = 16
_CHECKPOINT = 5
_PILOTS = 2
_ATTEMPTS = 4
_TOLERANCE = 0.1
_LIGHT = 4
_LIGHT_CHECKPOINT = 30


def initial_trajectories(problem: Problem, behavior, rng: np.random.Generator, *, thorough: bool = True) -> Motion:
    """A Motion of ``problem.n_frames`` frames meeting every constraint of `problem` exactly.

    COM groups reach their constraints by choosing among the model's own forward simulations;
    with `thorough` False they are simulated once, steered along their paths by the model where it
    declares ``group_guide`` (cheaper, with a common impulse on the group's agents), for callers
    that draw many initial trajectories and choose among those instead."""
    return _Initial(problem, behavior, rng, reach="thorough" if thorough else "steered").run()


def regenerate(problem: Problem, behavior, current: Motion, start: int, stop: int, rng: np.random.Generator) -> Motion:
    """`current` with frames start..stop (window boundaries) built anew, window by window as in
    ``initial_trajectories``: from `current`'s state at `start` (arriving velocity; at frame 0 the
    starting state, frames 0 and 1, kept exactly) to exactly its positions and velocities at
    `stop` (temporary continuity constraints, 3.4.1)."""
    builder = _Initial(problem, behavior, rng, reach="light")
    last = current.n_frames - 1
    state = _arriving(current, start)
    prior = current.state(start - 1) if start > 0 else None
    pieces = [Motion(positions=current.positions[: start + 1], dt=current.dt)]
    for a, b in windows(problem):
        if a < start or b > stop:
            continue
        end = _arriving(current, b) if b == stop and stop < last else None
        piece = builder._window(state, a, b, end=end, prior=prior)
        pieces.append(piece)
        state, prior = _state_at_end(piece, None), piece.state(-2)
    pieces.append(Motion(positions=current.positions[stop:], dt=current.dt))
    joined = builder._around_obstacles(_join(pieces, current.dt), start, stop)
    positions = np.array(joined.positions)
    if start == 0:  # the starting state: the simulation drifts to frame 1 up to rounding, a blend moves it
        positions[1] = current.positions[1]
    return Motion(positions=positions, dt=current.dt, channels=dict(current.channels))


def _arriving(motion: Motion, t: int) -> State:
    """The state at frame t with the velocity that arrives there (the one leaving, at frame 0)."""
    velocity = (motion.positions[t] - motion.positions[t - 1]) / motion.dt if t > 0 else motion.state(0).velocities
    return State(positions=motion.positions[t], velocities=velocity)


class _Path:
    """The B-spline through a point or COM sequence, over the frames it spans."""

    def __init__(self, track, problem):
        times = np.array([c.time for c in track])
        self.first, self.last = problem.frame(times[0]), problem.frame(times[-1])
        self.spline = track_path(times, [c.position for c in track])
        self.agents = problem.agents_of(track[0])
        self.is_point = isinstance(track[0], PointConstraint)
        self.members = {id(c) for c in track}
        self.frames = [problem.frame(t) for t in times]

    def spans(self, start, stop) -> bool:
        return self.first <= start and stop <= self.last


class _Initial:
    def __init__(self, problem, behavior, rng, reach="thorough"):
        self.problem, self.behavior, self.rng = problem, behavior, rng
        # how COM groups reach their constraints: "thorough" (a chain's start), "light" (a
        # proposal's draw: fewer simulations) or "steered" (one simulation, group_guide)
        thorough = reach == "thorough"
        self.rollouts, self.pilots, self.attempts = (_ROLLOUTS, _PILOTS, _ATTEMPTS) if thorough else (_LIGHT, 0, 1)
        self.checkpoint = _CHECKPOINT if thorough else _LIGHT_CHECKPOINT
        self.steer = reach == "steered" and capabilities(behavior).group_guide
        self.dt = problem.dt
        self.paths = [_Path(track, problem) for track in problem.tracks if len(track) >= 2]
        self.guided = capabilities(behavior).guide
        self.by_frame: dict[int, list] = {}
        for constraint in problem.constraints:
            self.by_frame.setdefault(problem.frame(constraint.time), []).append(constraint)

    def run(self) -> Motion:
        spans = windows(self.problem)
        first_constrained = min(self.by_frame, default=None)
        snapshot = self._snapshot()
        if first_constrained is None:
            state = State(positions=snapshot.positions, velocities=snapshot.velocities, extra=snapshot.extra)
            pieces = [self.behavior.forward(state, self.problem.n_frames - 1, self.rng)]
            return _join(pieces, self.dt)
        positions, velocities = self._configure(
            snapshot.positions, snapshot.velocities, self.by_frame[first_constrained], fixed={}
        )
        state = State(positions=positions, velocities=velocities)
        pieces = []
        if first_constrained > 0:
            lead = self.behavior.backward(state, first_constrained, self.rng)
            pinned = self.by_frame[first_constrained]
            if self._leads_forward(pinned):
                lead = self._lead_forward(lead, pinned)
                pieces.append(lead)
                state = _state_at_end(lead, None)
            else:
                pieces.append(lead)
                state = _state_at_end(lead, velocities)
        prior = pieces[-1].state(-2) if pieces else None
        for start, stop in spans:
            if stop <= first_constrained:
                continue
            piece = self._window(state, start, stop, prior=prior)
            pieces.append(piece)
            state, prior = _state_at_end(piece, None), piece.state(-2)
        return self._around_obstacles(_join(pieces, self.dt), -1, self.problem.n_frames)

    def _leads_forward(self, pinned) -> bool:
        """Whether the lead-in to the first constrained frame can be simulated forward: its
        constraints are COMs and points (for a model declaring ``guide``)."""
        points = [c for c in pinned if isinstance(c, PointConstraint)]
        coms = [c for c in pinned if isinstance(c, ComConstraint)]
        return len(points) + len(coms) == len(pinned) and (self.guided or not points)

    def _lead_forward(self, lead: Motion, pinned) -> Motion:
        """The lead-in simulated forward from the backward one's first frame (backward simulation
        is not forward-plausible), point-constrained agents kept on their backward paths: of
        _ROLLOUTS simulations, the one whose groups head best for their paths' next constraints
        (``_reach``'s landing), each group then moved by one translation over the whole lead-in,
        so its center is exactly met (the group's own motion unchanged)."""
        steps = lead.n_frames - 1
        points = {c.agent: lead.positions[:, c.agent] for c in pinned if isinstance(c, PointConstraint)}
        coms = [c for c in pinned if isinstance(c, ComConstraint)]
        heading = []  # (constraint, seconds to its path's next knot, the position there)
        for c in coms:
            path = next((p for p in self.paths if id(c) in p.members and p.frames[-1] > steps), None)
            if path is not None:
                knot = min(f for f in path.frames if f > steps)
                heading.append((c, (knot - steps) * self.dt, path.spline(knot * self.dt)))
        groups = []
        if self.steer:  # one simulation, each group steered along its backward path
            groups = [(list(self.problem.agents_of(c)), lead.positions[:, list(self.problem.agents_of(c))].mean(axis=1))
                      for c in coms]  # fmt: skip
            heading = []
        best, best_miss = None, np.inf
        for _ in range(self.rollouts if heading else 1):
            trial = self.behavior.forward(lead.state(0), steps, self.rng, **_guide_arguments(points, groups))
            miss = 0.0
            for c, ahead, target in heading:
                _, carried = _carried_on(trial.positions, list(self.problem.agents_of(c)), ahead, self.dt)
                landing = c.position + carried
                miss += float(np.sum((landing - target) ** 2))
            if miss < best_miss:
                best, best_miss = trial, miss
        positions = np.array(best.positions)
        free = np.ones((steps + 1, self.problem.n_agents), dtype=bool)
        free[:, list(points)] = False
        for c in coms:
            self._recentre(positions, free, steps, c, np.ones(steps + 1))
        return Motion(positions=positions, dt=self.dt, channels=_channels(best))

    # -- one window --------------------------------------------------------------------------

    def _window(
        self, state: State, start: int, stop: int, end: State | None = None, prior: State | None = None
    ) -> Motion:
        """Trajectories for frames start..stop from `state`; with `end`, ending exactly there.

        With `prior`, the state one frame before `start` (with the velocity leaving it), the
        forward simulation starts there: a simulation's first step carries no impulse, so starting
        one frame early joins the windows without a kink in the inferred wander."""
        steps = stop - start
        spanning = [p for p in self.paths if p.spans(start, stop)]
        if prior is None:
            forward = self._forward(state, start, stop, spanning)
        else:
            forward = self._forward(prior, start - 1, stop, spanning)[1:]
        positions = self._onto_paths(forward.positions, spanning, start, anchor=forward.positions[0])
        ending = [c for c in self.by_frame.get(stop, []) if not any(id(c) in p.members for p in spanning)]
        if not ending and end is None:
            return Motion(positions=positions, dt=self.dt, channels=_channels(forward))
        if end is None:
            fixed = {a: positions[-1, a] for p in spanning if p.is_point for a in p.agents}
            end_positions, end_velocities = self._configure(
                positions[-1],
                (positions[-1] - positions[-2]) / self.dt,
                self.by_frame[stop],
                fixed=fixed,
                start_positions=positions[0],
            )
        else:
            end_positions, end_velocities = np.array(end.positions), np.array(end.velocities)
        backward = self.behavior.backward(
            State(positions=end_positions, velocities=end_velocities),
            steps,
            self.rng,
            **self._guide(spanning, start, steps),
        )
        back = self._onto_paths(backward.positions, spanning, start, anchor=forward.positions[0])
        u = _blend_weights(steps)[:, None, None]
        blended = (1 - u) * positions + u * back
        if not spanning:
            blended = self._along_hermite(blended, state.velocities, end_velocities)
        blended[0], blended[-1] = positions[0], end_positions  # exactly, whatever the rounding
        return Motion(positions=blended, dt=self.dt, channels=_channels(forward))

    def _forward(self, state: State, first: int, stop: int, spanning) -> Motion:
        """Operation 1 from `state` at frame `first` to `stop`. Where COM paths span the window,
        each group reaches its constraint frames by the model's own draws (``_reach``), the
        stretch to each such frame drawn again, up to _ATTEMPTS times, while its centers end
        farther than _TOLERANCE sigma_com from their paths (the nearest attempt kept). Steering
        the group along its path instead added a common impulse to every agent at every frame,
        which a free flock never draws, and moving it onto its path afterwards costs an impulse at
        every frame of the move (bench/README.md)."""
        coms = [p for p in spanning if not p.is_point]
        knots = sorted({f for p in coms for f in p.frames if first + 1 < f <= stop})
        if not knots or self.steer:
            guide = self._guide(spanning, first, stop - first, steer=True)
            return self.behavior.forward(state, stop - first, self.rng, **guide)
        pieces, at, back = [], first, 0
        for knot in knots + ([stop] if knots[-1] < stop else []):
            aimed = [p for p in coms if knot in p.frames]
            best = None
            for _ in range(self.attempts if aimed else 1):
                attempt = self._reach(state, at, back, knot, aimed, spanning)
                if best is None or attempt[2] < best[2]:
                    best = attempt
                if best[2] <= (_TOLERANCE * self.problem.sigma_com) ** 2 * len(aimed):
                    break
            pieces += best[0]
            state, at, back = best[1], knot, 1
        return _join(pieces, self.dt)

    def _reach(self, state: State, at: int, back: int, knot: int, aimed, spanning) -> tuple[list, State, float]:
        """Pieces of motion from frame `at` (`state` at frame at - `back`) to `knot`, the state one
        frame before `knot`, and the summed squared miss of the `aimed` paths' centers there. From
        every checkpoint (each _CHECKPOINT frames) _ROLLOUTS forward simulations run to the next
        checkpoint, and the one kept is the one whose centers, carried on at their velocity to the
        knot, land nearest their paths there (in the last stretch, the one that ends nearest)."""
        pieces, miss = [], 0.0
        while at < knot:
            steps = min(knot - at, self.checkpoint) if aimed else knot - at
            # after the first stretch, each starts one frame back (as windows do, see _window)
            guide = self._guide(spanning, at - back, steps + back)
            ahead = (knot - at - steps) * self.dt  # seconds from the trial's end to the knot
            bias = [np.zeros(self.problem.dims) for _ in aimed]
            if aimed and ahead > 0 and self.pilots:
                whole = self._guide(spanning, at - back, knot - at + back)
                for _ in range(self.pilots):
                    pilot = self.behavior.forward(state, knot - at + back, self.rng, **whole)[back:]
                    for k, p in enumerate(aimed):
                        centre, carried = _carried_on(pilot.positions[: steps + 1], list(p.agents), ahead, self.dt)
                        bias[k] += (pilot.positions[-1, list(p.agents)].mean(axis=0) - centre - carried) / self.pilots
            best, miss = None, np.inf
            for _ in range(self.rollouts if aimed else 1):
                trial = self.behavior.forward(state, steps + back, self.rng, **guide)[back:]
                squared = 0.0
                for k, p in enumerate(aimed):
                    centre, carried = _carried_on(trial.positions, list(p.agents), ahead, self.dt)
                    landing = centre + carried + bias[k]
                    squared += float(np.sum((landing - p.spline(knot * self.dt)) ** 2))
                if squared < miss:
                    best, miss = trial, squared
            pieces.append(best)
            state, at, back = best.state(-2), at + steps, 1
        return pieces, state, (miss if aimed else 0.0)

    def _guide(self, spanning, start, steps, steer=False) -> dict:
        """Keyword arguments keeping point-path agents on their paths during simulation, so the
        others react to where they really are (for models declaring `guide`); with `steer`, in
        the "steered" reach, also steering COM-path groups along theirs (``group_guide``)."""
        times = (start + np.arange(steps + 1)) * self.dt
        points = {p.agents[0]: p.spline(times) for p in spanning if p.is_point} if self.guided else {}
        groups = [(list(p.agents), p.spline(times)) for p in spanning if not p.is_point] if steer and self.steer else []
        return _guide_arguments(points, groups)

    def _onto_paths(self, positions, spanning, start, anchor) -> np.ndarray:
        """Operation 2: translate constrained agents onto their paths, the others with them."""
        if not spanning:
            return positions.copy()
        times = (start + np.arange(len(positions))) * self.dt
        moved = positions.copy()
        shift = np.zeros_like(positions)
        owner = np.full(self.problem.n_agents, -1)  # which path moved each agent
        on_point_path = set()
        for index, path in enumerate(spanning):
            if path.is_point:
                agent = path.agents[0]
                shift[:, agent] = path.spline(times) - positions[:, agent]
                owner[agent] = index
                on_point_path.add(agent)
        for index, path in enumerate(spanning):
            if not path.is_point:
                free = [a for a in path.agents if a not in on_point_path]
                if not free:
                    continue
                current = (positions[:, list(path.agents)] + shift[:, list(path.agents)]).sum(axis=1)
                delta = (len(path.agents) * path.spline(times) - current) / len(free)
                delta = self._at_knots(delta, path, start)  # near the path: held on it only at the knots
                shift[:, free] += delta[:, None, :]
                owner[free] = index
        carriers = np.flatnonzero(owner >= 0)
        point_carriers = np.array(sorted(on_point_path), dtype=int)
        for agent in np.flatnonzero(owner < 0):
            pool = point_carriers if len(point_carriers) else carriers
            shift[:, agent] = shift[:, self._leader(pool, anchor, agent)]
        moved += shift
        return moved

    @staticmethod
    def _at_knots(delta, path, start) -> np.ndarray:
        """A COM path's per-frame correction `delta` kept only at the window's ends and at the
        path's constraint frames, joined by a clamped cubic: between them the group keeps the
        wander of its own agents. Moving it onto the path at every frame would cancel that wander,
        and each agent would pay for it as an impulse at every frame (the wander is a unit vector)."""
        last = len(delta) - 1
        knots = sorted({0, last} | {f - start for f in path.frames if 0 < f - start < last})
        return CubicSpline(knots, delta[knots], bc_type="clamped")(np.arange(len(delta)))

    def _along_hermite(self, positions, start_velocity, end_velocity) -> np.ndarray:
        """Move the COM along the Hermite curve joining the window's end states."""
        steps = len(positions) - 1
        com = positions.mean(axis=1)
        curve = CubicHermiteSpline(
            [0.0, steps * self.dt], com[[0, -1]], np.stack([start_velocity.mean(axis=0), end_velocity.mean(axis=0)])
        )
        return positions + (curve(np.arange(steps + 1) * self.dt) - com)[:, None, :]

    def _leader(self, pool, positions, agent) -> int:
        """The constrained agent whose move an unconstrained one copies (Problem.follow)."""
        if self.problem.follow == "random":
            return int(self.rng.choice(pool))
        return int(pool[np.argmin(np.linalg.norm(positions[pool] - positions[agent], axis=1))])

    # -- obstacles ---------------------------------------------------------------------------

    def _around_obstacles(self, motion: Motion, start: int, stop: int) -> Motion:
        """`motion` with its agents kept clear of the problem's obstacles at frames start+1 ..
        stop-1; the other frames, and the agents of point and shape constraints at theirs, are
        held. The simulations avoid obstacles, but blending them and moving groups onto their
        paths can carry agents into one, where the model's avoidance is at its strongest and each
        agent-frame costs thousands in log g."""
        if not self.problem.obstacles or self.problem.clearance <= 0:
            return motion
        # only frames start..stop take part: the frames beyond are held, and their zero pushes
        # spread nothing into the window
        first, last = max(start, 0), min(stop, motion.n_frames - 1)
        held = np.zeros((last + 1 - first, motion.n_agents), dtype=bool)
        held[: start + 1 - first] = held[stop - first :] = True
        coms = []
        for c in self.problem.constraints:
            f = self.problem.frame(c.time)
            if not isinstance(c, ComConstraint) and first <= f <= last:
                held[f - first, list(self.problem.agents_of(c))] = True
            elif isinstance(c, ComConstraint) and start < f < stop:
                coms.append((f - first, c))
        positions = np.array(motion.positions)
        positions[first : last + 1] = self._clear_of_obstacles(positions[first : last + 1], held, coms)
        return Motion(positions=positions, dt=motion.dt, channels=dict(motion.channels))

    def _clear_of_obstacles(self, positions, held, coms) -> np.ndarray:
        """`positions` (T, N, D) with every agent-frame not `held` (T, N) at least
        ``Problem.clearance`` outside each obstacle: pushed out along the surface normal, the
        pushes spread over neighbouring frames (a Gaussian of _SPREAD seconds) so that paths bend
        round instead of sliding along the surface, and pushed again. Each COM constraint
        (frame, constraint) stays met: the group's agents that are not held take the difference,
        spread the same way."""
        clearance = self.problem.clearance
        if not self.problem.obstacles or clearance <= 0:
            return positions
        free = ~held
        original = positions.copy()
        frames = np.arange(len(positions))
        spread = _SPREAD / self.dt
        bumps = [np.exp(-0.5 * ((frames - f) / spread) ** 2) for f, _ in coms]
        for round_ in range(_PUSHES):
            for (f, c), bump in zip(coms, bumps):
                self._recentre(positions, free, f, c, bump)
            for obstacle in self.problem.obstacles:
                depth = obstacle.signed_distance(positions.reshape(-1, self.problem.dims)).reshape(held.shape)
                near = free & (depth < clearance)
                if near.any() and len(positions) == 1:  # a configuration: towards the group
                    centres = np.broadcast_to(positions.mean(axis=1)[:, None], positions.shape)[near]
                    positions[near] = _pushed_out(obstacle, positions[near], centres, clearance)
                elif near.any():  # a motion: along the normal, so that paths stay continuous
                    positions[near] += (clearance - depth[near])[:, None] * obstacle.surface_normal(positions[near])
            if round_ < _PUSHES - 1:
                shift = gaussian_filter1d(positions - original, spread, axis=0, mode="nearest")
                positions = original + shift * free[:, :, None]
        for f, c in coms:  # exactly, by agents the last pushes left clear enough to take it
            depth = np.min([o.signed_distance(positions[f]) for o in self.problem.obstacles], axis=0)
            self._recentre(positions, free, f, c, frames == f, roomy=depth >= 2 * clearance)
        return positions

    def _recentre(self, positions, free, f, constraint, weights, roomy=None) -> None:
        """Move the free agents of a COM constraint at frame f (those `roomy` there, if any)
        so its center is met exactly there, by that move times `weights` at the other frames."""
        agents = np.array(self.problem.agents_of(constraint))
        movable = agents[free[f, agents]]
        if roomy is not None and roomy[movable].any():
            movable = movable[roomy[movable]]
        if len(movable):
            error = (len(agents) * constraint.position - positions[f, agents].sum(axis=0)) / len(movable)
            positions[:, movable] += weights[:, None, None] * free[:, movable, None] * error

    # -- constrained configurations (3.3.1) ---------------------------------------------------

    def _snapshot(self) -> State:
        """The last state of a short unconstrained simulation from a random flock."""
        flock = random_flock(n_agents=self.problem.n_agents, dims=self.problem.dims, rng=self.rng)
        return self.behavior.forward(flock, _WARM_UP, self.rng).state(-1)

    def _configure(self, snapshot, velocities, constraints, *, fixed, start_positions=None):
        """Positions and velocities meeting `constraints`, built from the snapshot; `fixed` agents
        keep their given positions. Each constrained agent is placed by a rigid motion of the
        snapshot, which the unconstrained agents then copy from a leader (section 3.3.1)."""
        positions, out_velocities = snapshot.copy(), velocities.copy()
        transforms: dict[int, tuple] = {}  # agent -> the rigid motion that placed it
        for agent, where in fixed.items():
            positions[agent] = where
        points = [c for c in constraints if isinstance(c, PointConstraint)]
        for c in points:
            if c.agent not in fixed:
                rotation = rigid.turn(velocities[c.agent], c.velocity)
                transforms[c.agent] = (rotation, c.position - rotation @ snapshot[c.agent])
                positions[c.agent], out_velocities[c.agent] = c.position, c.velocity
        pinned = set(fixed) | {c.agent for c in points}
        for c in constraints:
            free = [a for a in self.problem.agents_of(c) if a not in pinned]
            if isinstance(c, PointConstraint) or not free:
                continue
            origins = None if start_positions is None else start_positions[free]
            positions[free], out_velocities[free], motion = self._place(c, free, snapshot, velocities, origins)
            if isinstance(c, ComConstraint):  # exact COM, moving only the free agents
                agents = list(self.problem.agents_of(c))
                positions[free] += (len(agents) * c.position - positions[agents].sum(axis=0)) / len(free)
            transforms.update(dict.fromkeys(free, motion))
            pinned.update(free)
        placed = np.array(sorted(transforms), dtype=int)
        for agent in (a for a in range(self.problem.n_agents) if a not in pinned and len(placed)):
            rotation, translation = transforms[self._leader(placed, snapshot, agent)]
            positions[agent] = rigid.apply(rotation, translation, snapshot[agent])
            out_velocities[agent] = rigid.rotate(rotation, velocities[agent])
        held = np.zeros((1, self.problem.n_agents), dtype=bool)
        held[0, list(fixed)] = True
        for c in constraints:
            if not isinstance(c, ComConstraint):
                held[0, list(self.problem.agents_of(c))] = True
        coms = [(0, c) for c in constraints if isinstance(c, ComConstraint)]
        return self._clear_of_obstacles(positions[None], held, coms)[0], out_velocities

    def _place(self, constraint, free, snapshot, velocities, origins):
        """(positions, velocities, rigid motion) of the `free` agents of a COM or shape constraint:
        the snapshot's subset turned to the constraint's velocity and moved to its target (a shape:
        samples inside it), the agents matched to the slots keeping their travel from `origins`
        (the window start; default where the rigid motion puts them) short."""
        rotation = rigid.turn(velocities[free].mean(axis=0), constraint.velocity)
        target = constraint.position if isinstance(constraint, ComConstraint) else constraint.shape.centroid()
        translation = target - rotation @ snapshot[free].mean(axis=0)
        placed = rigid.apply(rotation, translation, snapshot[free])
        slots, slot_velocities = placed, rigid.rotate(rotation, velocities[free])
        # the mean velocity too, not only its direction: a flock placed at the snapshot's speed
        # where its path asks for another spends the next window catching up
        slot_velocities = slot_velocities - slot_velocities.mean(axis=0) + constraint.velocity
        if isinstance(constraint, ShapeConstraint):
            slots = _fill(constraint.shape, len(free), self.rng)
        order = _matching(slots, placed if origins is None else origins, self.rng)
        return slots[order], slot_velocities[order], (rotation, translation)


# -- helpers ----------------------------------------------------------------------------------


def _pushed_out(obstacle, points, centres, clearance) -> np.ndarray:
    """`points` moved to `clearance` outside `obstacle`: towards their group's centre where that
    is clear (the first point of the segment at that distance, by bisection), so that an agent
    does not leave its group round the obstacle's far side; along the surface normal elsewhere."""
    out = points + (clearance - obstacle.signed_distance(points))[:, None] * obstacle.surface_normal(points)
    towards = obstacle.signed_distance(centres) >= clearance
    if towards.any():
        low, high = np.zeros(int(towards.sum())), np.ones(int(towards.sum()))
        start, step = points[towards], centres[towards] - points[towards]
        for _ in range(30):
            middle = (low + high) / 2
            clear = obstacle.signed_distance(start + middle[:, None] * step) >= clearance
            low, high = np.where(clear, low, middle), np.where(clear, middle, high)
        out[towards] = start + high[:, None] * step
    return out


def _blend_weights(steps: int) -> np.ndarray:
    """u = -(2t^3 - 3t^2) for t from 0 to 1 over the window."""
    t = np.linspace(0.0, 1.0, steps + 1)
    return 3 * t**2 - 2 * t**3


def _fill(shape, count: int, rng) -> np.ndarray:
    """`count` points uniform in `shape`, pushed apart by a few relaxation steps, kept inside."""
    lower, upper = shape.bounds()
    points = shape.sample(count, rng)
    volume = np.prod(upper - lower) * np.mean(shape.contains(rng.uniform(lower, upper, size=(512, len(lower)))))
    spacing = 0.7 * (max(volume, 1e-12) / count) ** (1 / len(lower))
    for _ in range(_RELAXATION_STEPS):
        offsets = points[:, None, :] - points[None, :, :]
        distance = np.linalg.norm(offsets, axis=2) + np.eye(count) * 1e9
        push = np.where(distance < spacing, (spacing - distance) / np.maximum(distance, 1e-12), 0.0)
        points = points + 0.25 * (offsets * push[:, :, None]).sum(axis=1)
        depth = shape.signed_distance(points)
        outside = depth > -1e-9
        points[outside] -= (depth[outside] + 1e-6 * spacing)[:, None] * shape.surface_normal(points[outside])
    return points


def _matching(slots: np.ndarray, origins: np.ndarray, rng) -> np.ndarray:
    """order such that agent k (at origins[k]) takes slots[order[k]]: a sampled matching with a
    short total squared travel (the optimal one on costs perturbed by noise)."""
    cost = ((origins[:, None, :] - slots[None, :, :]) ** 2).sum(axis=2)
    scale = float(np.median(cost)) or 1.0
    _, order = linear_sum_assignment(cost + rng.gumbel(0.0, 0.05 * scale, cost.shape))
    return order


def _carried_on(positions, agents, seconds: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The center of `agents` at the last frame of `positions`, and how far the velocity of its
    last step carries it in `seconds`: where a group heads."""
    centre = positions[-2:, agents].mean(axis=1)
    return centre[-1], seconds * (centre[-1] - centre[0]) / dt


def _guide_arguments(points: dict, groups: list) -> dict:
    """A model's ``guide`` (agent -> path) and ``group_guide`` ((agents, path) pairs) keyword
    arguments, each left out where empty."""
    found = {"guide": points} if points else {}
    if groups:
        found["group_guide"] = groups
    return found


def _state_at_end(motion: Motion, velocities) -> State:
    end = motion.state(-1)
    return end if velocities is None else State(positions=end.positions, velocities=velocities, extra=end.extra)


def _channels(motion: Motion) -> dict:
    return {name: motion.channels[name] for name in motion.channels}


def _join(pieces, dt) -> Motion:
    """Windows share their boundary frames: keep each boundary once. The model channels every
    piece carries (whatever the model names them) are joined the same way."""

    def joined(arrays):
        return np.concatenate([arrays[0]] + [a[1:] for a in arrays[1:]])

    shared = set.intersection(*(set(p.channels) for p in pieces))
    channels = {name: joined([p.channels[name] for p in pieces]) for name in sorted(shared)}
    return Motion(positions=joined([p.positions for p in pieces]), dt=dt, channels=channels)
