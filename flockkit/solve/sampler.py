"""The plausibility sampler of paper 004, section 3.4, and ``solve``.

log g(A) = sum over frames of [log g_w (the behavior's log_plausibility) + the objective terms].
Each iteration picks a proposal move at random (default bump 0.6, velocity 0.3, regenerate 0.1),
and accepts its candidate with probability min(1, exp(log g(candidate) - log g(current))).
Scoring is incremental: a proposal reports the frames and agents it changed, and only frames
within the behavior's ``plausibility_reach`` of them are re-scored (all of them for a model that
does not declare one); objective terms depend on their own frame only.
"""

from __future__ import annotations

import math
from collections import Counter

import attrs
import numpy as np

from .._arrays import count
from ..constraints import ComConstraint, PointConstraint, Problem
from ..errors import ValidationError
from ..motion import Motion
from ..registry import get
from .initial import initial_trajectories
from .windows import windows

DEFAULT_PROPOSALS = {"bump": 0.6, "velocity": 0.3, "regenerate": 0.1}
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
    """What a proposal move may read: the problem, the behavior model, the windows of the initial
    trajectories, the current per-frame log g (`scores`) and the point-constrained agent-frames
    (`pinned`, boolean (T, N)), which a move must leave exactly where they are."""

    problem: Problem
    behavior: object
    windows: tuple
    scores: np.ndarray
    pinned: np.ndarray

    def free_agents(self, start: int, stop: int) -> np.ndarray:
        """Agents without a point constraint at frames start <= t < stop."""
        return np.flatnonzero(~self.pinned[max(start, 0) : stop].any(axis=0))


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


def feasible(problem: Problem, motion: Motion) -> bool:
    """Whether `motion` meets the constraints as a solution must: point constraints to 1e-9, COM
    constraints within 3 sigma_com, every shape-constrained agent inside its shape."""
    for c, residual in zip(problem.constraints, residuals(problem, motion)):
        limit = 1e-9 if isinstance(c, PointConstraint) else 3 * problem.sigma_com if isinstance(c, ComConstraint) else 0.0
        if residual > limit:
            return False
    return True


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
    """Per-frame log g of motions for one problem, behavior and set of objective terms."""

    def __init__(self, problem, behavior, objectives):
        self.problem, self.behavior, self.objectives = problem, behavior, objectives
        self.reach = getattr(behavior, "plausibility_reach", None)

    def frames(self, motion: Motion, start: int = 0, stop: int | None = None) -> np.ndarray:
        stop = motion.n_frames if stop is None else stop
        total = np.asarray(self.behavior.log_plausibility(motion, start, stop), dtype=np.float64).copy()
        for objective in self.objectives:
            total += objective.log_terms(motion, self.problem, start, stop)
        return total

    def affected(self, proposal: Proposal, n_frames: int) -> tuple[int, int]:
        """The frames whose score the proposal's changes can alter."""
        if self.reach is None:
            return 0, n_frames
        return max(0, proposal.start - self.reach), min(n_frames, proposal.stop + self.reach)


STABLE_WINDOW = 100  # iterations per running mean for the `stable` stopping rule


def run_chain(problem, behavior, objectives, moves, initial: Motion, iterations: int, rng, *, callback=None, progress=None, stable=None):
    """One chain from `initial`: (best motion, its log g, Trace). The best motion is the most
    plausible sample that is `feasible`. `moves` is a list of (name, move, probability). With `stable`, stop early once the mean log g over the last
    STABLE_WINDOW iterations differs from the mean over the window before by at most `stable`
    times its size."""
    scorer = Scorer(problem, behavior, objectives)
    names = [name for name, _, _ in moves]
    weights = np.array([p for _, _, p in moves], dtype=float)
    weights = weights / weights.sum()
    spans, pinned = tuple(windows(problem)), pinned_frames(problem)
    current, scores = initial, scorer.frames(initial)
    total = float(scores.sum())
    best, best_total = current, total  # the initial trajectories meet every constraint
    log_g, tried, accepted = np.empty(iterations), [], np.zeros(iterations, dtype=bool)
    for iteration in range(iterations):
        pick = int(rng.choice(len(moves), p=weights))
        context = ProposalContext(problem=problem, behavior=behavior, windows=spans, scores=_readonly(scores), pinned=pinned)
        proposal = moves[pick][1].propose(current, context, rng)
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


def solve(problem: Problem, *, behavior="boids", iterations=1000, chains=1, seed=None, proposals=None,
          objectives=DEFAULT_OBJECTIVES, stable=None, n_jobs=1, callback=None, progress=False) -> Solution:
    """Constrained, plausible motion for `problem` (paper 004).

    Parameters
    ----------
    behavior : str
        Name of the behavior model, made with the problem's ``dt`` (and ``obstacles``, if any).
    iterations : int
        Sampler iterations per chain (at most, with `stable`); 0 returns the initial trajectories.
    stable : float, optional
        Stop a chain early once its running mean of log g stabilizes: the mean over the last 100
        iterations within this fraction of the mean over the 100 before.
    chains, n_jobs : int
        Independent chains (each from its own initial trajectories), run by joblib workers.
    seed : int, optional
        Seeds everything: the same seed gives the same Solution.
    proposals : dict, optional
        Proposal name -> probability (normalized); default bump 0.6, velocity 0.3, regenerate 0.1.
    objectives : sequence of str
        Objective terms added to the behavior's log plausibility.
    callback : callable, optional
        ``callback(chain, iteration, log_g, accepted)`` after every iteration (n_jobs=1 only).
    progress : bool
        A progress bar over all iterations.
    """
    if not isinstance(problem, Problem):
        raise ValidationError(f"solve: problem must be a flockkit.Problem; got {type(problem).__name__}")
    iterations = count(iterations, field="iterations", minimum=0)
    chains = count(chains, field="chains")
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or n_jobs == 0:
        raise ValidationError(f"n_jobs must be a non-zero integer; got {n_jobs!r}")
    if callback is not None and n_jobs != 1:
        raise ValidationError("solve: a callback runs in this process only; use n_jobs=1 with it")
    proposals = dict(DEFAULT_PROPOSALS if proposals is None else proposals)
    for name, probability in proposals.items():
        if isinstance(probability, bool) or not isinstance(probability, (int, float)) or not probability >= 0:
            raise ValidationError(f"solve: the probability of proposal {name!r} must be a number >= 0; got {probability!r}")
    if iterations and not sum(proposals.values()) > 0:
        raise ValidationError("solve: proposals need a positive total probability")
    objectives = tuple(objectives)
    if stable is not None and (isinstance(stable, bool) or not isinstance(stable, (int, float)) or not stable >= 0):
        raise ValidationError(f"solve: stable must be None or a number >= 0; got {stable!r}")
    _components(problem, behavior, proposals, objectives)  # fail early on unknown names
    seeds = np.random.SeedSequence(seed).spawn(chains)
    arguments = (problem, behavior, proposals, objectives, iterations, stable)
    if n_jobs == 1:
        bar = _bar(progress, chains * iterations)
        results = []
        for index, chain_seed in enumerate(seeds):
            tick = None if bar is None else (lambda done, base=index * iterations: bar.update(base + done - bar.n))
            report = None if callback is None else (lambda i, g, a, chain=index: callback(chain, i, g, a))
            results.append(_chain(*arguments, chain_seed, report, tick))
        if bar is not None:
            bar.close()
    else:
        from joblib import Parallel, delayed

        results = Parallel(n_jobs=n_jobs)(delayed(_chain)(*arguments, chain_seed, None, None) for chain_seed in seeds)
    order = sorted(range(chains), key=lambda k: -results[k][1])
    acceptance = _acceptance([r[2] for r in results])
    best = results[order[0]][0]
    return Solution(
        motion=best, motions=tuple(results[k][0] for k in order), log_g=tuple(results[k][1] for k in order),
        trace=tuple(r[2] for r in results), acceptance=acceptance, residuals=residuals(problem, best),
    )


def _components(problem, behavior_name, proposals, objectives):
    params = {"dt": problem.dt}
    if problem.obstacles:
        params["obstacles"] = problem.obstacles
    behavior = get("behavior", behavior_name, **params)
    moves = [(name, get("proposal", name), p) for name, p in proposals.items() if p > 0]
    terms = [get("objective", name) for name in objectives]
    return behavior, moves, terms


def _chain(problem, behavior_name, proposals, objectives, iterations, stable, seed, callback, progress):
    behavior, moves, terms = _components(problem, behavior_name, proposals, objectives)
    rng = np.random.default_rng(seed)
    initial = initial_trajectories(problem, behavior, rng)
    if not iterations:
        scores = Scorer(problem, behavior, terms).frames(initial)
        return initial, float(scores.sum()), Trace(log_g=np.empty(0), proposals=(), accepted=np.zeros(0, dtype=bool))
    return run_chain(problem, behavior, terms, moves, initial, iterations, rng, callback=callback, progress=progress, stable=stable)


def _acceptance(traces) -> dict:
    tried, taken = Counter(), Counter()
    for trace in traces:
        for name, accepted in zip(trace.proposals, trace.accepted):
            tried[name] += 1
            taken[name] += bool(accepted)
    return {name: taken[name] / tried[name] for name in tried}


def _readonly(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.setflags(write=False)
    return view


def _bar(progress, total):
    if not progress or not total:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="sampling", unit="it")
