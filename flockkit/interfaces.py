"""The extension kinds of flockkit: one ``typing.Protocol`` per kind, its contract in the docstring.

A plugin registers a *factory* for a component (usually its class); ``flockkit.get(kind, name,
**params)`` calls ``factory(**params)`` and checks the result against the protocol of that kind.
Registration checks that each method below exists and accepts the parameters named here.
``flockkit.testing.check_plugin(kind, component)`` checks the behavior behind the contract.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from .motion import Configuration, Motion, State

__all__ = [
    "BehaviorModel",
    "ConfigurationMetric",
    "GraphBuilder",
    "WalkStrategy",
    "ProposalMove",
    "Objective",
]


@runtime_checkable
class BehaviorModel(Protocol):
    """A group behavior model with the three operations of paper 004, section 3.1.

    Contract
    --------
    ``forward(initial, steps, rng)``
        Simulate `steps` >= 0 steps from `initial` and return a Motion of ``steps + 1`` frames
        whose first frame has exactly the positions of `initial` (and, where ``steps >= 1``,
        its velocities, by the Motion velocity convention). Model arrays the model carries from
        step to step (``State.extra``) are returned as Motion channels of the same names.
    ``backward(final, steps, rng)``
        Return ``steps + 1`` frames whose last frame has exactly the positions (and velocities)
        of `final`, plausibly leading up to it. Paper 004 does this by simulating forward with
        perception reversed, from `final` with its velocities reversed, and reversing time.
    ``log_plausibility(motion, start=0, stop=None)``
        Entry k is the log density, summed over agents, of the random choices (for boids: the
        wander impulses) that the model would have made at frame ``start + k`` to produce the
        motion; ``stop=None`` means the end. Frames at which no choice can be inferred contribute
        0. The sum over all frames is log g_w. Evaluating a window equals slicing a full
        evaluation, so a sampler can re-score only the frames it changed.

    All three are deterministic given the Generator `rng`, never mutate their inputs, return
    finite float64 arrays for finite inputs, and raise ``flockkit.errors.ValidationError`` for
    bad arguments (negative steps, a window outside the motion, unsupported dimensions).

    ``forward`` and ``backward`` may also accept an optional keyword ``progress``: a callable
    taking the number of steps completed so far. ``flockkit.simulate`` passes it when present.
    They may also accept ``guide``: a mapping of agent index to (steps + 1, D) positions those
    agents take (keyframed) while the others react to them; the constrained-animation initial
    trajectories use it where offered. And a model may declare ``plausibility_reach``: how many
    frames on each side of a changed frame its ``log_plausibility`` can change (the sampler then
    re-scores only those).
    """

    def forward(self, initial: State, steps: int, rng: np.random.Generator) -> Motion: ...

    def backward(self, final: State, steps: int, rng: np.random.Generator) -> Motion: ...

    def log_plausibility(self, motion: Motion, start: int = 0, stop: int | None = None) -> np.ndarray: ...


@runtime_checkable
class ConfigurationMetric(Protocol):
    """A distance between two group configurations (paper 000, section 4.2).

    Contract
    --------
    ``compare(a, b)``
        Return a ``flockkit.Alignment`` whose ``distance`` >= 0 is the mean squared distance
        between `a` and `b` after the best rigid motion and agent assignment found, with
        ``a.positions[i] ~= rotation @ b.positions[assignment[i]] + translation``. Symmetric up to
        the search, zero for identical configurations, invariant to rigid motion and to the order
        of agents.

    Optional, used by graph builders to go faster:

    ``lower_bound(a, b)``
        A proven lower bound on ``compare(a, b).distance``, much cheaper than `compare`.
    ``pairs_within(configurations, threshold)``
        Integer array (P, 2) of pairs (i, j), i < j, each once, including every pair whose
        ``compare`` distance is at most `threshold` (pairs left out are proven farther apart).
        It may take ``rows=(start, stop)``: then only the pairs with start <= i < stop, so that
        a builder can share the job among workers.
    ``pairwise(configurations, pairs=None)``
        Distances (P,) of ``compare(configurations[i], configurations[j])`` for each row (i, j) of
        `pairs`; without `pairs`, every i < j in row-major order (``scipy`` ``pdist`` order).
    """

    def compare(self, a: Configuration, b: Configuration): ...


@runtime_checkable
class GraphBuilder(Protocol):
    """Builds a motion graph from a recording (paper 000, section 4.3).

    Contract
    --------
    ``build(motion, metric, rng)``
        Return a ``flockkit.MotionGraph`` whose clips are frame ranges of `motion`, whose
        transitions join configurations that `metric` finds similar, and whose every node can be
        reached from every other (dead ends trimmed). Deterministic given `rng`.
    """

    def build(self, motion: Motion, metric: ConfigurationMetric, rng: np.random.Generator): ...


@runtime_checkable
class WalkStrategy(Protocol):
    """Chooses a path through a motion graph (paper 000, section 5).

    Contract
    --------
    ``walk(graph, rng, duration)``
        Return a ``flockkit.Walk`` (start pose and edge sequence) covering at least `duration`
        seconds of synthesized motion. Deterministic given `rng`; raises a flockkit error rather
        than looping when its goal cannot be met.
    """

    def walk(self, graph, rng: np.random.Generator, duration: float): ...


@runtime_checkable
class ProposalMove(Protocol):
    """Proposes a change to a constrained animation (paper 004, section 3.4.1).

    Contract
    --------
    ``propose(current, context, rng)``
        Return a proposal (the changed Motion plus the frames and agents it changed), or None when
        this move has nothing to offer. Never mutates `current`; keeps every point constraint
        in `context` exactly; reports every frame and agent it changed.
    """

    def propose(self, current: Motion, context, rng: np.random.Generator): ...


@runtime_checkable
class Objective(Protocol):
    """One family of log terms of the sampler's objective (paper 004, section 3.4.2).

    Contract
    --------
    ``log_terms(motion, problem, start=0, stop=None)``
        Entry k is this objective's log term at frame ``start + k``: finite or -inf, never NaN,
        and a window equals the slice of a full evaluation.
    """

    def log_terms(self, motion: Motion, problem, start: int = 0, stop: int | None = None) -> np.ndarray: ...


# kind name -> protocol; the single table the registry and the conformance kit read.
PROTOCOLS: dict[str, type] = {
    "behavior": BehaviorModel,
    "metric": ConfigurationMetric,
    "builder": GraphBuilder,
    "walk": WalkStrategy,
    "proposal": ProposalMove,
    "objective": Objective,
}
