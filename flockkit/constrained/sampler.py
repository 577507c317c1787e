"""The plausibility sampler of paper 004, section 3.4, and ``solve``.

log g(A) = sum over frames of [log g_w (the behavior's log_plausibility) + the objective terms].
Each iteration picks a proposal move at random (default bump 0.6, velocity 0.1, regenerate 0.1),
and accepts its candidate with probability min(1, exp(log g(candidate) - log g(current))). Every
ADAPT_EVERY proposals of a move, the scale it is given (``ProposalContext.scale``, at most 1)
halves if fewer than a fifth were accepted and doubles if more than half were; a move none of
whose last ADAPT_EVERY proposals was accepted is picked half as often (down to a RAREST share of
its probability; back up as it is accepted again), so that moves which cannot improve the
current motion, such as regenerate after a refined start, stop costing most of the time.
No move may change a held agent-frame (``held_frames``: point constraints, and the starting
state, frames 0 and 1, which no term scores); a proposal that does is refused.
Scoring is incremental: a proposal reports the frames and agents it changed, and only frames
within the behavior's ``plausibility_reach`` of them are re-scored (all of them for a model that
does not declare one); objective terms depend on their own frame only.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping

import attrs
import numpy as np

from .. import parallel
from .._progress import progress_bar
from ..errors import ValidationError
from ..interfaces import capabilities
from ..motion import Motion
from ..registry import get, label, require_dims, resolve
from ..validate import allocation, integer, number
from ..validate import seed as validate_seed
from .aims import com_aims
from .initial import initial_trajectories
from .least_squares import refine as refine_motion
from .problem import ComConstraint, PointConstraint, Problem
from .reach import shapes_apart, speeds, unconstrained, warn_beyond
from .windows import windows

# Paper 004 draws velocity (re-timing) moves with weight 0.3. Accepted most often (a quarter of
# tries), they leave the free agents' impulses a little larger than a forward simulation's; at 0.1
# they do not, and the shipped scenarios' log g stays within their spread (bench/README.md).
DEFAULT_PROPOSALS = {"bump": 0.6, "velocity": 0.1, "regenerate": 0.1}
DEFAULT_OBJECTIVES = ("com", "shape", "flocks")


@attrs.frozen(kw_only=True, eq=False)
class Proposal:
    """A candidate from a proposal move: the whole new motion, and what changed in it.

    Every changed value lies at frames start <= t < stop and at the listed agents.
    """

    motion: Motion
    start: int
    stop: int
    agents: tuple[int, ...]


@attrs.frozen(kw_only=True, eq=False)
class ProposalContext:
    """What a proposal move may read: the problem (in ``solve``, with its COM constraints at
    the aims the initial trajectories met, ``flockkit.constrained.com_aims``), the behavior model, the
    windows of the initial trajectories, the current per-frame log g (`scores`), the agent-frames
    a move must leave exactly where they are (`pinned`, boolean (T, N); in ``solve``, see
    ``held_frames``: the point-constrained ones and the starting state, frames 0 and 1 of every
    agent), and `scale`, a factor for the size of a move's changes that the sampler adapts to how
    often the move's proposals are accepted (a motion near its most plausible takes only small
    changes)."""

    problem: Problem
    behavior: object
    windows: tuple
    scores: np.ndarray
    pinned: np.ndarray
    scale: float = 1.0

    def free_agents(self, start: int, stop: int) -> np.ndarray:
        """Agents not pinned at any of the frames start <= t < stop."""
        return np.flatnonzero(~self.pinned[max(start, 0) : stop].any(axis=0))

    @property
    def first_movable(self) -> int:
        """The first frame at which some agent is not pinned: the frames before it (in ``solve``,
        the starting state) are held whole, so a move's changes begin here at the earliest."""
        movable = ~self.pinned.all(axis=1)
        return int(np.argmax(movable)) if movable.any() else len(movable)


@attrs.frozen(kw_only=True, eq=False)
class Trace:
    """One chain's iterations: log g after each, the move tried, and whether it was accepted."""

    log_g: np.ndarray
    proposals: tuple[str, ...]
    accepted: np.ndarray


@attrs.frozen(kw_only=True, eq=False)
class Solution:
    """The result of ``solve``.

    Attributes
    ----------
    motion : Motion
        The most plausible sample found (highest log g over every chain) among those that meet
        the constraints: point constraints exactly, COM constraints within 3 sigma_com, every
        shape-constrained agent inside its shape (the sampler keeps COM and shape constraints
        only through the objective, so samples in between may stray a little).
    motions : tuple of Motion
        Each chain's most plausible sample, ranked by log g (best first).
    log_g : tuple of float
        Their log g, in the same order.
    trace : tuple of Trace
        One per chain, in chain order.
    acceptance : dict
        Proposal name -> fraction of its proposals accepted, over every chain.
    residuals : tuple of float
        Per constraint of ``problem.constraints`` for `motion`: distance of a point-constrained
        agent, or of a center of mass, from its target; for a shape, the largest distance of a
        constrained agent outside it (0 when all are inside).
    """

    motion: Motion
    motions: tuple
    log_g: tuple
    trace: tuple
    acceptance: dict
    residuals: tuple


def pinned_frames(problem: Problem) -> np.ndarray:
    """(T, N) boolean: True where a point constraint fixes an agent at a frame."""
    pinned = np.zeros((problem.n_frames, problem.n_agents), dtype=bool)
    for c in problem.constraints:
        if isinstance(c, PointConstraint):
            pinned[problem.frame(c.time), c.agent] = True
    return pinned


# Frames 0 and 1 of every agent: the starting state, positions and the velocity between them. No
# term scores it (a model infers no impulse before frame 1, and frame 1's reads the velocity only
# as the one it changes), so a move that changed it would buy motion for free: a runner "started"
# at 25 length units per second and coasted down to the model's speed at no cost. The initial
# trajectories set it (from a simulated flock, placed on the constraints at frame 0), and every
# move and refine keep it.
START_FRAMES = 2


def held_frames(problem: Problem) -> np.ndarray:
    """(T, N) boolean: the agent-frames no move may change, ``pinned_frames`` and the starting
    state (the first START_FRAMES frames of every agent)."""
    held = pinned_frames(problem)
    held[:START_FRAMES] = True
    return held


def unmet(problem: Problem, motion: Motion) -> list[tuple[int, float, float]]:
    """(index, residual, tolerance) of each constraint of `problem` that `motion` does not meet as
    a solution must: point constraints to 1e-9, COM constraints within 3 sigma_com, every
    shape-constrained agent inside its shape."""
    found = []
    for index, (c, residual) in enumerate(zip(problem.constraints, residuals(problem, motion))):
        if isinstance(c, PointConstraint):
            limit = 1e-9
        else:
            limit = 3 * problem.sigma_com if isinstance(c, ComConstraint) else 0.0
        if residual > limit:
            found.append((index, residual, limit))
    return found


def feasible(problem: Problem, motion: Motion) -> bool:
    """Whether `motion` meets every constraint as a solution must (see :func:`unmet`)."""
    return not unmet(problem, motion)


def residuals(problem: Problem, motion: Motion) -> tuple[float, ...]:
    """See Solution.residuals."""
    found = []
    for c in problem.constraints:
        frame, agents = problem.frame(c.time), list(problem.agents_of(c))
        if isinstance(c, PointConstraint):
            found.append(float(np.linalg.norm(motion.positions[frame, c.agent] - c.position)))
        elif isinstance(c, ComConstraint):
            found.append(float(np.linalg.norm(motion.positions[frame, agents].mean(axis=0) - c.position)))
        else:
            found.append(float(max(0.0, np.max(c.shape.signed_distance(motion.positions[frame, agents])))))
    return tuple(found)


class Scorer:
    """Per-frame log g of motions for one problem, behavior and set of objective terms.

    With ``Problem.keyframed_weight`` other than 1 and a behavior declaring
    ``Capabilities(residuals=True)``, each agent's share of the behavior's term, - |r|^2 / 2 of its
    residuals, is weighed by ``Problem.agent_weights``; the per-frame constant the residuals are
    subtracted from is read once, from the first motion scored whole."""

    def __init__(self, problem, behavior, objectives):
        self.problem, self.behavior, self.objectives = problem, behavior, objectives
        declared = capabilities(behavior)
        self.reach = declared.plausibility_reach
        weights = problem.agent_weights()
        self.weights = weights if declared.residuals and np.any(weights != 1.0) else None
        self._constant = None

    def frames(self, motion: Motion, start: int = 0, stop: int | None = None) -> np.ndarray:
        stop = motion.n_frames if stop is None else stop
        total = self._plausibility(motion, start, stop)
        for objective in self.objectives:
            total += objective.log_terms(motion, self.problem, start, stop)
        return total

    def _plausibility(self, motion: Motion, start: int, stop: int) -> np.ndarray:
        if self.weights is None:
            return np.asarray(self.behavior.log_plausibility(motion, start, stop), dtype=np.float64).copy()
        if self._constant is None:
            whole = self._squares(motion, 0, motion.n_frames)
            plain = np.asarray(self.behavior.log_plausibility(motion), dtype=np.float64)
            self._constant = plain + 0.5 * whole.sum(axis=1)
        return self._constant[start:stop] - 0.5 * (self._squares(motion, start, stop) @ self.weights)

    def _squares(self, motion: Motion, start: int, stop: int) -> np.ndarray:
        """(frames, N): each agent's summed squared residuals."""
        residuals = np.asarray(self.behavior.plausibility_residuals(motion, start, stop), dtype=np.float64)
        return np.einsum("tnk,tnk->tn", residuals, residuals)

    def affected(self, proposal: Proposal, n_frames: int) -> tuple[int, int]:
        """The frames whose score the proposal's changes can alter."""
        if self.reach is None:
            return 0, n_frames
        return max(0, proposal.start - self.reach), min(n_frames, proposal.stop + self.reach)


STABLE_WINDOW = 100  # iterations per running mean for the `stable` stopping rule
ADAPT_EVERY = 25  # proposals of a move between adaptations of its scale and share
RAREST = 1 / 8  # the smallest share of its probability a move that is never accepted keeps


def run_chain(
    problem,
    behavior,
    objectives,
    moves,
    initial: Motion,
    iterations: int,
    rng,
    *,
    callback=None,
    progress=None,
    stable=None,
    aims=None,
):
    """One chain from `initial`: (best motion, its log g, Trace). The best motion is the most
    plausible sample that is `feasible`. `moves` is a list of (name, move, probability); they see
    `aims` (default `problem`: the problem with its COM constraints where the initial trajectories
    met them, ``com_aims``) as the context's problem. With `stable`, stop early once the mean log
    g over the last STABLE_WINDOW iterations differs from the mean over the window before by at
    most `stable` times its size."""
    scorer = Scorer(problem, behavior, objectives)
    names = [name for name, _, _ in moves]
    weights = np.array([p for _, _, p in moves], dtype=float)
    weights = weights / weights.sum()
    shares = np.ones(len(moves))  # each move's share of its probability
    spans, pinned = tuple(windows(problem)), held_frames(problem)
    current, scores = initial, scorer.frames(initial)
    total = float(scores.sum())
    best, best_total = current, total  # the initial trajectories meet every constraint
    log_g, tried, accepted = np.empty(iterations), [], np.zeros(iterations, dtype=bool)
    scales, tries, takes = np.ones(len(moves)), np.zeros(len(moves), dtype=int), np.zeros(len(moves), dtype=int)
    for iteration in range(iterations):
        chances = weights * shares
        pick = int(rng.choice(len(moves), p=chances / chances.sum()))
        context = ProposalContext(
            problem=problem if aims is None else aims, behavior=behavior, windows=spans,
            scores=_readonly(scores), pinned=pinned, scale=float(scales[pick]),
        )  # fmt: skip
        proposal = moves[pick][1].propose(current, context, rng)
        if proposal is not None and _moves_held(proposal, current, pinned):
            proposal = None  # refused: a held agent-frame moved
        if proposal is not None:
            start, stop = scorer.affected(proposal, current.n_frames)
            fresh = scorer.frames(proposal.motion, start, stop)
            change = float(fresh.sum() - scores[start:stop].sum())
            if not math.isnan(change) and (change >= 0 or math.log(rng.random()) < change):
                current, accepted[iteration] = proposal.motion, True
                scores[start:stop] = fresh
                total = float(scores.sum())
                if total > best_total and feasible(problem, current):
                    best, best_total = current, total
        log_g[iteration] = total
        tried.append(names[pick])
        tries[pick], takes[pick] = tries[pick] + 1, takes[pick] + accepted[iteration]
        if tries[pick] == ADAPT_EVERY:  # aim each move's size at about a fifth to a half accepted
            rate = takes[pick] / ADAPT_EVERY
            scales[pick] = min(1.0, scales[pick] * (0.5 if rate < 0.2 else 2.0 if rate > 0.5 else 1.0))
            shares[pick] = max(RAREST, shares[pick] / 2) if rate == 0 else min(1.0, shares[pick] * 2)
            tries[pick] = takes[pick] = 0
        if callback is not None:
            callback(iteration, total, bool(accepted[iteration]))
        if progress is not None:
            progress(iteration + 1)
        if stable is not None and iteration + 1 >= 2 * STABLE_WINDOW:
            recent = log_g[iteration + 1 - STABLE_WINDOW : iteration + 1].mean()
            before = log_g[iteration + 1 - 2 * STABLE_WINDOW : iteration + 1 - STABLE_WINDOW].mean()
            if abs(recent - before) <= stable * max(abs(before), 1.0):
                log_g, accepted = log_g[: iteration + 1], accepted[: iteration + 1]
                break
    return best, best_total, Trace(log_g=log_g, proposals=tuple(tried), accepted=accepted)


# the behavior model solve uses when none is named (a convenience default: any installed model works)
DEFAULT_BEHAVIOR = "boids"


def solve(
    problem: Problem,
    *,
    behavior=DEFAULT_BEHAVIOR,
    behavior_params: dict | None = None,
    iterations=1000,
    refine=40,
    starts=1,
    chains=1,
    seed=None,
    proposals=None,
    objectives=DEFAULT_OBJECTIVES,
    stable=None,
    n_jobs=None,
    callback=None,
    progress=False,
) -> Solution:
    """Constrained, plausible motion for `problem` (paper 004).

    Point and shape constraints are met exactly; COM constraints within 3 ``problem.sigma_com``:
    each chain's initial trajectories (refined and regenerated alike) meet the COM constraints of
    each track at their aims (``flockkit.constrained.com_aims``), and the sampler scores every COM
    against its own position.

    Parameters
    ----------
    behavior : str or behavior model
        An installed behavior model's name, made with the problem's ``dt``, `behavior_params`
        and, for a problem with obstacles, ``obstacles`` (the model must declare
        ``Capabilities(obstacles=True)``); or an instance, used as it is configured.
    behavior_params : dict, optional
        Parameters of a behavior made by name (``dt`` and ``obstacles`` come from the problem).
    iterations : int
        Sampler iterations per chain (at most, with `stable`); 0 returns the starting motion.
    refine : int
        For a behavior declaring ``Capabilities(residuals=True)``: at most this many least-squares
        steps (``flockkit.constrained.refine``) improve each chain's initial trajectories before
        sampling, so that the motion looks like the model made it; 0 samples from the initial
        trajectories as they are (paper 004).
    starts : int
        Initial trajectories drawn per chain; the chain refines and samples the one whose
        uncoupled (cheap) refine steps reach the highest log g among those meeting the
        constraints: SCREEN_STEPS of them, or with more than SURVIVORS draws FIRST_STEPS for each
        and SCREEN_STEPS for the SURVIVORS best (none without `refine`). Draws differ much, but
        the best start is often one where agents no constraint holds take on part of the
        constrained agents' cost, which leaves their motion unlike a free flock's. So the default
        is 1; obstacle-squeeze and arrows, whose every agent is in a constrained group, ask for
        120 and 5 (bench/README.md has the figures).
    stable : float, optional
        Stop a chain early once its running mean of log g stabilizes: the mean over the last 100
        iterations within this fraction of the mean over the 100 before.
    chains, n_jobs : int
        Independent chains (each from its own initial trajectories), run by joblib workers
        (``n_jobs=None``: what ``joblib.parallel_config`` says, else 1; see ``flockkit.parallel``).
        Every component is resolved here, once; workers receive instances.
    seed : int, optional
        Seeds everything: the same seed gives the same Solution, whatever `n_jobs` is.
    proposals : mapping or sequence, optional
        Proposal name -> probability (normalized), or (name or instance, probability) pairs;
        default bump 0.6, velocity 0.1, regenerate 0.1. ``Solution.acceptance`` names an
        instance by its class.
    objectives : sequence
        Objective terms (names or instances) added to the behavior's log plausibility.
    callback : callable, optional
        ``callback(chain, iteration, log_g, accepted)`` after every iteration (n_jobs=1 only).
    progress : bool
        A progress bar over all iterations.
    """
    if not isinstance(problem, Problem):
        raise ValidationError(f"solve: problem must be a flockkit.Problem; got {type(problem).__name__}")
    iterations = integer(iterations, "iterations", minimum=0)
    refine = integer(refine, "refine", minimum=0)
    starts = integer(starts, "starts", minimum=1)
    chains = integer(chains, "chains", minimum=1)
    n_jobs = parallel.jobs(n_jobs)
    if callback is not None and n_jobs != 1:
        raise ValidationError("solve: a callback runs in this process only; use n_jobs=1 with it")
    stable = number(stable, "solve: stable", minimum=0, optional=True)
    seed = validate_seed(seed)
    size = f"{problem.n_frames} frames of {problem.n_agents} agents in {problem.dims}D"
    # per chain: the current, proposed and best motions and a channel; the trace: 3 numbers an iteration
    allocation(4 * chains * problem.n_frames * problem.n_agents * problem.dims, f"solve: {chains} chains of {size}")
    allocation(3 * chains * iterations, f"solve: the trace of {chains} chains of {iterations} iterations")
    model = _behavior(problem, behavior, behavior_params)
    aims = problem
    if problem.tracks or shapes_apart(problem):  # speeds given or implied to judge, and COM tracks to aim
        free = unconstrained(problem, model, seed)
        lowest, highest, fastest = np.percentile(speeds(free), [10, 90, 99])
        warn_beyond(problem, free, float(fastest))
        if problem.tracks:
            aims = com_aims(problem, (float(lowest), float(highest)))
    moves = _moves(problem, DEFAULT_PROPOSALS if proposals is None else proposals, iterations)
    terms = [_component("objective", spec, problem) for spec in objectives]
    seeds = np.random.SeedSequence(seed).spawn(chains)
    arguments = (problem, aims, model, moves, terms, iterations, refine, starts, stable)
    if n_jobs == 1:
        results = _chains_here(arguments, seeds, iterations, callback, progress)
    else:
        results = list(parallel.imap(_chain, [(*arguments, s, None, None) for s in seeds], n_jobs=n_jobs))
    order = sorted(range(chains), key=lambda k: -results[k][1])
    best = results[order[0]][0]
    return Solution(
        motion=best,
        motions=tuple(results[k][0] for k in order),
        log_g=tuple(results[k][1] for k in order),
        trace=tuple(r[2] for r in results),
        acceptance=_acceptance([r[2] for r in results]),
        residuals=residuals(problem, best),
    )


def _chains_here(arguments, seeds, iterations, callback, progress) -> list:
    """Every chain in this process, with the callback and one progress bar over all iterations."""
    results = []
    with progress_bar(progress and len(seeds) * iterations > 0) as report:
        for index, chain_seed in enumerate(seeds):
            tick = (
                None
                if report is None
                else (lambda done, base=index * iterations: report(base + done, len(seeds) * iterations, "sampling"))
            )
            chain_callback = None if callback is None else (lambda i, g, a, chain=index: callback(chain, i, g, a))
            results.append(parallel.one_thread(_chain)(*arguments, chain_seed, chain_callback, tick))
    return results


def _behavior(problem: Problem, spec, params):
    """The behavior model of a solve: made by name with the problem's dt (and obstacles), or the
    given instance; it must handle the problem's dimensions and, with obstacles, declare them."""
    params = dict(params or {})
    if isinstance(spec, str):
        clash = sorted({"dt", "obstacles"} & set(params))
        if clash:
            raise ValidationError(f"solve: behavior_params {', '.join(clash)} come from the problem; leave them out")
        model = get("behavior", spec, dt=problem.dt, **params)
        if problem.obstacles and capabilities(model).obstacles:
            model = get("behavior", spec, dt=problem.dt, obstacles=problem.obstacles, **params)
    else:
        model = resolve("behavior", spec, **params)
    if problem.obstacles and not capabilities(model).obstacles:
        raise ValidationError(
            f"solve: the problem has {len(problem.obstacles)} obstacles but behavior {label(spec)} does not avoid "
            "obstacles (it does not declare Capabilities(obstacles=True))"
        )
    require_dims("behavior", model, problem.dims, f"a {problem.dims}D problem", spec=spec)
    return model


def _component(kind: str, spec, problem: Problem):
    component = resolve(kind, spec)
    require_dims(kind, component, problem.dims, f"a {problem.dims}D problem", spec=spec)
    return component


def _moves(problem: Problem, proposals, iterations) -> list:
    """(label, move, probability) for each proposal with a positive probability; labels are the
    names given, or class names of instances (numbered where two are alike)."""
    pairs = list(proposals.items()) if isinstance(proposals, Mapping) else list(proposals)
    moves, seen = [], Counter()
    for index, pair in enumerate(pairs):
        if not (isinstance(pair, tuple) and len(pair) == 2):
            raise ValidationError(f"solve: proposals[{index}] must be a (proposal, probability) pair; got {pair!r}")
        spec, probability = pair
        probability = number(probability, f"solve: the probability of proposal {label(spec)!r}", minimum=0)
        seen[label(spec)] += 1
        name = label(spec) if seen[label(spec)] == 1 else f"{label(spec)}#{seen[label(spec)]}"
        if probability > 0:
            moves.append((name, _component("proposal", spec, problem), probability))
    if iterations and not moves:
        raise ValidationError("solve: proposals need a positive total probability")
    return moves


def _chain(problem, aims, behavior, moves, terms, iterations, refine, starts, stable, seed, callback, progress):
    """One chain: the best of `starts` initial trajectories meeting `aims` (`problem` with its
    COM constraints at their aims, ``com_aims``) exactly, refined, then sampled; scored and judged
    on `problem`."""
    rng = np.random.default_rng(seed)
    initial = _start(problem, aims, behavior, terms, refine, starts, rng)
    if not iterations:
        scores = Scorer(problem, behavior, terms).frames(initial)
        return initial, float(scores.sum()), Trace(log_g=np.empty(0), proposals=(), accepted=np.zeros(0, dtype=bool))
    return run_chain(
        problem,
        behavior,
        terms,
        moves,
        initial,
        iterations,
        rng,
        callback=callback,
        progress=progress,
        stable=stable,
        aims=aims,
    )


# Ranking a chain's starts by uncoupled refine steps (cheap): with more draws than SURVIVORS,
# every draw is scored after FIRST_STEPS (towards the most regular motion, sample=False) and the
# SURVIVORS best of them again after SCREEN_STEPS; with fewer, every draw after SCREEN_STEPS.
# The draws differ more than steps tell them apart, so many draws ranked cheaply, then the best
# few ranked again, beat few draws ranked carefully (bench/README.md, obstacle-squeeze).
FIRST_STEPS = 1
SCREEN_STEPS = 10
SURVIVORS = 10


def _start(problem, aims, behavior, terms, refine, starts, rng) -> Motion:
    """A chain's starting motion: of `starts` initial trajectories, the one ranked best (see
    SURVIVORS) by its log g after uncoupled refine steps (as drawn, without refine, or where the
    steps leave a constraint unmet), refined by `refine` steps that move only the agents of some
    constraint."""
    refines = bool(refine) and capabilities(behavior).residuals
    pinned, scorer = pinned_frames(aims), Scorer(problem, behavior, terms)
    # refine leaves the agents of no constraint as simulated: least squares on the total let them
    # carry part of the constrained agents' cost, and their impulses stop looking like a free flock's
    constrained = set().union(*(problem.agents_of(c) for c in problem.constraints))
    pinned[:, [a for a in range(problem.n_agents) if a not in constrained]] = True

    def rank(motion, steps, sample=True) -> float:
        if refines:
            screened = refine_motion(aims, behavior, motion, pinned, rng, iterations=min(refine, steps),
                                     coupling=False, sample=sample)  # fmt: skip
            motion = screened if feasible(problem, screened) else motion
        return float(scorer.frames(motion).sum())

    many = starts > SURVIVORS
    kept = []  # (score, draw): the SURVIVORS best so far
    for _ in range(starts):
        draw = initial_trajectories(aims, behavior, rng, thorough=not many)  # many: choosing among draws
        if starts == 1:
            score = 0.0  # nothing to rank
        elif many:  # a step towards the most regular motion: no forward simulation to draw targets from
            score = rank(draw, FIRST_STEPS, sample=False)
        else:
            score = rank(draw, SCREEN_STEPS)
        kept.append((score, draw))
        kept.sort(key=lambda pair: -pair[0])  # stable: of equal scores, the first drawn
        del kept[SURVIVORS:]
    if many and refines:
        kept = [(rank(draw, SCREEN_STEPS), draw) for _, draw in kept]
    best = max(kept, key=lambda pair: pair[0])[1]
    # the full refine starts again from the draw: its targets are drawn from the motion it starts
    # from, and from a screened one (residuals already model-like) it would keep them as they are
    if refines:
        refined = refine_motion(aims, behavior, best, pinned, rng, iterations=refine)
        if feasible(problem, refined):
            return refined
    return best


def _acceptance(traces) -> dict:
    tried, taken = Counter(), Counter()
    for trace in traces:
        for name, accepted in zip(trace.proposals, trace.accepted):
            tried[name] += 1
            taken[name] += bool(accepted)
    return {name: taken[name] / tried[name] for name in tried}


def _moves_held(proposal: Proposal, current: Motion, held: np.ndarray) -> bool:
    """Whether the proposal changes an agent-frame of `held` (T, N): at the frames it reports, and
    at the starting state whatever it reports."""
    new, old = proposal.motion.positions, current.positions
    if not np.array_equal(new[:START_FRAMES], old[:START_FRAMES]):
        return True
    start, stop = max(proposal.start, START_FRAMES), proposal.stop
    rows = held[start:stop]
    return bool(rows.any()) and not np.array_equal(new[start:stop][rows], old[start:stop][rows])


def _readonly(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.setflags(write=False)
    return view
