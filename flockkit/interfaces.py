"""The extension kinds of flockkit: one ``typing.Protocol`` per kind, its contract in the docstring.

A plugin registers a *factory* for a component (usually its class); ``flockkit.get(kind, name,
**params)`` calls ``factory(**params)`` and checks the result against the protocol of that kind
(``flockkit.kinds.KINDS`` says which protocol, hook and capabilities each kind has).
Registration checks that each method below exists and accepts the parameters named here.
``flockkit.testing.check_plugin(kind, component)`` checks the behavior behind the contract.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import attrs
import numpy as np

from .errors import ValidationError

if TYPE_CHECKING:
    from .motion import Configuration, Motion, State

__all__ = [
    "Capabilities",
    "capabilities",
    "BehaviorModel",
    "ConfigurationMetric",
    "GraphBuilder",
    "WalkStrategy",
    "ProposalMove",
    "Objective",
    "Segmenter",
    "Controller",
    "Guided",
    "GroupGuided",
    "Residuals",
    "Coupling",
    "SimulationProgress",
    "BuildProgress",
    "LowerBound",
    "PairsWithin",
    "Pairwise",
    "Skinned",
    "RootMotionSource",
    "BatchedController",
    "LiveController",
]


def _dims(value) -> tuple[int, ...]:
    try:
        dims = tuple(value)
    except TypeError:
        dims = ()
    valid = all(isinstance(d, int | np.integer) and not isinstance(d, bool) and d in (2, 3) for d in dims)
    if not dims or not valid or len(set(dims)) != len(dims):
        raise ValidationError(
            f"Capabilities.dims must be a non-empty tuple of distinct dimensions from (2, 3); got {value!r}"
        )
    return tuple(sorted(int(d) for d in dims))


def _flag(name):
    def check(instance, attribute, value):
        if not isinstance(value, bool):
            raise ValidationError(f"Capabilities.{name} must be True or False; got {value!r}")

    return check


def _reach(instance, attribute, value):
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
        raise ValidationError(f"Capabilities.plausibility_reach must be None or an integer >= 0; got {value!r}")


@attrs.frozen(kw_only=True)
class Capabilities:
    """What a component supports beyond the required methods of its kind: declared, never guessed.

    A component declares it as a ``capabilities`` attribute (of its class or of the instance);
    :func:`capabilities` reads it, and gives these defaults when there is none. The core, the CLI
    and the conformance kit read only this declaration: they never look at signatures or
    attributes to find out what a component can do. Registration checks that every operation a
    component declares is there with the documented parameters, and that it declares only fields
    its kind reads (``flockkit.kinds.KINDS[kind].fields``).

    Attributes
    ----------
    dims : tuple of int
        The dimensions the component handles, from (2, 3). Every kind. The kit checks only these;
        ``simulate`` and ``solve`` refuse other dimensions with a message naming this field.
    guide : bool
        Behavior: ``forward`` and ``backward`` take ``guide``, a mapping of agent index to the
        (steps + 1, D) positions that agent takes (keyframed) while the others react to it. The
        initial trajectories of ``solve`` guide point-constrained agents along their paths.
    group_guide : bool
        Behavior: ``forward`` takes ``group_guide``, a sequence of (agents, path) pairs, path the
        (steps + 1, D) positions that group's center of mass should follow: the model biases its
        own random choices so that the group drifts along the path instead of wherever chance
        takes it (loosely: it is steered, not placed). The initial trajectories of ``solve`` steer
        COM-constrained groups along their paths, and then only move them onto the path at the
        window's ends and its constraints' times, instead of at every frame.
    obstacles : bool
        Behavior: the factory takes ``obstacles``, a sequence of flockkit regions the model
        avoids. ``solve`` passes a Problem's obstacles to a model it makes by name, and refuses a
        problem with obstacles for a model without this.
    plausibility_reach : int or None
        Behavior: changing positions at frame f changes ``log_plausibility`` only at frames
        f - reach .. f + reach. The sampler then re-scores only those frames after a proposal;
        None (unknown) re-scores every frame.
    residuals : bool
        Behavior: it offers ``plausibility_residuals(motion, start=0, stop=None)``, an array
        (stop - start, N, K) whose squares, summed over agents and components and halved, are
        what ``log_plausibility`` subtracts from a constant per frame (for boids: each wander
        impulse over its sigma). ``solve`` then improves its initial trajectories by least
        squares on them before sampling (``flockkit.constrained.refine``).
    coupling : bool
        Behavior, with ``residuals``: it offers ``plausibility_coupling(motion)``, a scipy sparse
        matrix (T N K, T N D) of the derivatives of each agent's residuals (rows, flattened
        (frame, agent, component)) with respect to *other* agents' positions (columns, flattened
        (frame, agent, dimension)), for the pairs that matter (boids: every seen neighbor). Refine
        measures each agent's own derivatives by finite differences with every agent moved at once,
        which credits an agent with its neighbors' pull; with the coupling, its steps see how
        neighbors push and pull each other, and refined starts come much closer to the model's
        own motion (bench/README.md).
    progress : bool
        Behavior (``forward`` and ``backward``) and builder (``build``): the operation takes
        ``progress``, a callable ``progress(done, total, stage)`` it calls as work completes
        (`stage` a short description; a new stage restarts the count). ``simulate`` and
        ``build_graph`` draw a progress bar with it when asked.
    lower_bound, pairs_within, pairwise : bool
        Metric: it offers that method (see ``ConfigurationMetric``). Builders use ``pairs_within``
        or else ``lower_bound`` to prune, and ``pairwise`` to compute many distances at once; the
        kit checks each declared one.
    targets : bool
        Walk: the factory takes ``target`` (a ``flockkit.Features`` of one arrow per output frame,
        or (time, vector) keyframes, that the walk's motion should follow), ``features`` (the
        graph's source arrows, one per source frame) and ``avoid`` (source frames, per output
        frame, to fall out of step with): what a ``flockkit.Scene`` walks its objects with.
    clip_player : bool
        Controller: the factory takes ``clip`` (a ``flockkit.SkeletalClip``) and ``rate`` (its
        playback speed): what crowd files and ``flockkit.crowd.ground_speed`` make per stream.
    root_motion : bool
        Controller: it offers ``root_motion(times)``, where the stream's root has gone on the
        ground at each time (``RootMotionSource``): what a crowd's agents advance by when their
        motion comes from their clips (``Crowd(root_motion=...)``, ``Driver(root_motion="clip")``).
    batch : bool
        Controller: it offers ``batch(controllers)`` (``BatchedController``), one evaluator for
        many controllers of its class and joint count at once: a ``StreamPool`` advances all such
        streams in one call a frame, writing their poses in place into its store, instead of
        calling each stream's ``pose``.
    live : bool
        Controller: its pose depends on inputs fed each frame (``LiveController``: ``inputs``
        and ``feed``), not on time alone: a pool evaluates it every frame at that frame's time,
        never ahead, so that what is fed before an ``update`` shows in that update's poses.
    skin : bool
        Segmenter: it needs the skin of what it segments: ``segment`` takes ``skin``, a
        ``flockkit.mesh.MeshSkin`` with one row per point of the motion (joints, hierarchy and
        each point's weights). ``flockkit.segment`` passes an ``AnimatedMesh``'s skin (welded like
        its points) and refuses a source without one; the kit segments its inputs with skins.
    """

    dims: tuple = attrs.field(default=(2, 3), converter=_dims)
    guide: bool = attrs.field(default=False, validator=_flag("guide"))
    group_guide: bool = attrs.field(default=False, validator=_flag("group_guide"))
    obstacles: bool = attrs.field(default=False, validator=_flag("obstacles"))
    plausibility_reach: int | None = attrs.field(default=None, validator=_reach)
    residuals: bool = attrs.field(default=False, validator=_flag("residuals"))
    coupling: bool = attrs.field(default=False, validator=_flag("coupling"))
    progress: bool = attrs.field(default=False, validator=_flag("progress"))
    lower_bound: bool = attrs.field(default=False, validator=_flag("lower_bound"))
    pairs_within: bool = attrs.field(default=False, validator=_flag("pairs_within"))
    pairwise: bool = attrs.field(default=False, validator=_flag("pairwise"))
    targets: bool = attrs.field(default=False, validator=_flag("targets"))
    clip_player: bool = attrs.field(default=False, validator=_flag("clip_player"))
    root_motion: bool = attrs.field(default=False, validator=_flag("root_motion"))
    batch: bool = attrs.field(default=False, validator=_flag("batch"))
    live: bool = attrs.field(default=False, validator=_flag("live"))
    skin: bool = attrs.field(default=False, validator=_flag("skin"))

    def __attrs_post_init__(self):
        if self.coupling and not self.residuals:
            raise ValidationError("Capabilities.coupling needs residuals=True: it gives the residuals' derivatives")

    def declared(self) -> dict:
        """The fields that differ from the defaults."""
        default = Capabilities()
        return {
            f.name: getattr(self, f.name)
            for f in attrs.fields(Capabilities)
            if getattr(self, f.name) != getattr(default, f.name)
        }


def capabilities(component) -> Capabilities:
    """The ``Capabilities`` that `component` (an instance or its class) declares, or the defaults.

    Raises ValidationError if its ``capabilities`` attribute is something else."""
    declared = getattr(component, "capabilities", None)
    if declared is None:
        return Capabilities()
    if not isinstance(declared, Capabilities):
        name = getattr(component, "__name__", None) or type(component).__name__
        raise ValidationError(f"{name}.capabilities must be a flockkit.Capabilities; got {type(declared).__name__}")
    return declared


@runtime_checkable
class BehaviorModel(Protocol):
    """A group behavior model with the three operations of paper 004, section 3.1.

    Contract
    --------
    ``forward(initial, steps, rng)``
        Simulate `steps` >= 0 steps from `initial` and return a Motion of ``steps + 1`` frames
        whose first frame has exactly the positions of `initial` (and, where ``steps >= 1``,
        its velocities, by the Motion velocity convention: frame 1 is ``initial.positions +
        dt * initial.velocities``, so the model's first random choice acts at frame 1). The
        Motion's dt is the model's time step. Model arrays the model carries from step to step
        (``State.extra``) are returned as Motion channels of the same names.
    ``backward(final, steps, rng)``
        Return ``steps + 1`` frames whose last frame has exactly the positions (and velocities)
        of `final`, plausibly leading up to it. Paper 004 does this by simulating forward with
        perception reversed, from `final` with its velocities reversed, and reversing time.
    ``log_plausibility(motion, start=0, stop=None)``
        Entry k is the log density, summed over agents, of the random choices (for boids: the
        wander impulses) that the model would have made at frame ``start + k`` to produce the
        motion; ``stop=None`` means the end. Frames at which no choice can be inferred contribute
        0. The sum over all frames is log g_w. The motion is scored at its own time step,
        ``motion.dt`` (a model that can only score the step it simulates raises ValidationError
        for a motion of another dt). Evaluating a window equals slicing a full
        evaluation, so a sampler can re-score only the frames it changed.

    All three are deterministic given the Generator `rng`, never mutate their inputs, return
    finite float64 arrays for finite inputs, and raise ``flockkit.errors.ValidationError`` for
    bad arguments (negative steps, a window outside the motion, unsupported dimensions).

    Optional, declared in ``Capabilities`` (``guide``, ``obstacles``, ``plausibility_reach``,
    ``residuals``, ``coupling``, ``progress``), never guessed from signatures.
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
        ``a.positions[i] ~= rotation @ b.positions[assignment[i]] + translation``. Symmetric
        (``compare(b, a).distance`` equals it to a relative 1e-6: search both ways, or so that
        the order cannot matter), zero for identical configurations, invariant to rigid motion
        and to the order of agents. Anything but two ``flockkit.Configuration`` of one size and
        dimension raises ``flockkit.errors.ValidationError``.

    Optional, each declared in ``Capabilities`` (``lower_bound``, ``pairs_within``,
    ``pairwise``), used by graph builders to go faster and checked by the kit:

    ``lower_bound(a, b)``
        A proven lower bound on ``compare(a, b).distance``, much cheaper than `compare`: a
        Python or numpy float.
    ``pairs_within(configurations, threshold, *, rows=None)``
        Integer array (P, 2) of pairs (i, j), i < j, each once, including every pair whose
        ``compare`` distance is at most `threshold` (pairs left out are proven farther apart).
        With ``rows=(start, stop)``, only the pairs with start <= i < stop, so that a builder can
        share the job among workers.
    ``pairwise(configurations, pairs=None)``
        A float64 numpy array (P,): ``compare(configurations[i], configurations[j])``'s distance for each row (i, j) of
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
        reached from every other (dead ends trimmed). Deterministic given `rng`. A builder
        that declares ``Capabilities(progress=True)`` takes ``progress`` as for behaviors.
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


@runtime_checkable
class Segmenter(Protocol):
    """Splits a group of points into parts that move independently (paper 002, section 4.1).

    Contract
    --------
    ``segment(motion, rng)``
        Return a ``flockkit.Segmentation`` of `motion`'s points (agents): one label per point,
        every part non-empty. Points that move together share a part; points that never move are
        not in a part with moving ones. Deterministic given `rng`; the partition does not depend
        on the order of the points (only the names of the parts may).
    """

    def segment(self, motion: Motion, rng: np.random.Generator): ...


@runtime_checkable
class Controller(Protocol):
    """Produces the pose of one animation stream over time: the tree of operations of paper 003,
    section 3.4 (a clip, a blend of two children, children combined by blend masks, ...).

    Contract
    --------
    ``skeleton``
        An attribute: the ``flockkit.Skeleton`` its poses are for.
    ``pose(times)``
        A ``flockkit.Pose`` of shape (len(times),) for `times` (a 1D array of seconds >= 0 on the
        stream's own clock): unit rotations, finite translations, one per joint of ``skeleton``.
        A function of time alone: the pose at t is the same whether asked alone, in a batch or
        after other times. Negative or non-finite times raise ValidationError.
    ``events(start, stop)``
        The ``flockkit.Event`` s whose times fall in [start, stop) of the stream's clock, in order
        of time; consecutive windows split them without loss or repeat.
    """

    def pose(self, times): ...

    def events(self, start: float, stop: float): ...


class RootMotionSource(Protocol):
    """The operation a controller declaring ``Capabilities(root_motion=True)`` offers.

    ``root_motion(times)``
        A float array (len(times), 4): at each time (seconds >= 0 on the stream's clock, checked
        as ``pose`` checks them), the ground transform from the root at time 0 to the root then,
        in the skeleton's model space and units: a translation (x, y, z, 0 along the skeleton's
        up axis) and a heading (radians about the up axis, unwrapped: turns accumulate), as
        ``flockkit.crowd.RootMotion.played`` gives them. Zero at time 0; a function of time
        alone; continuous where the poses are (a loop adds its motion, it does not jump back).
    """

    def root_motion(self, times): ...


class BatchedController(Protocol):
    """The operation a controller declaring ``Capabilities(batch=True)`` offers.

    ``batch(controllers)``
        An evaluator of `controllers` (a sequence of instances of the controller's class, this
        one among them, all of one joint count) with one method, ``write(index, times, out,
        rows, stride)``: for each i, the pose of ``controllers[index[i]]`` at ``times[i]``
        (seconds on its stream's clock) written into the flat float32 array `out`, joint j's
        rotation (x, y, z, w) at ``out[rows[i] + stride * j : ... + 4]`` and its translation at
        the three floats after, nothing else touched. Equal to ``pose`` at those times, rounded
        to float32; one call for every i, so no Python runs per controller. Its ``nbytes``
        attribute, if it has one, is the bytes it holds beyond the controllers (what
        ``StreamPool.memory`` counts).
    """

    def batch(self, controllers): ...


class LiveController(Protocol):
    """The operations a controller declaring ``Capabilities(live=True)`` offers: a state machine
    fed each frame (a locomotion controller fed speed and turn rate by a driver).

    ``inputs``
        An attribute: a mapping of each input's name to its (low, high) range.
    ``feed(**values)``
        Sets inputs (names from ``inputs``, numbers in range; others raise ValidationError). The
        next ``pose`` call shows them.
    ``pose(times)``
        As ``Controller.pose``, asked one time a frame by a pool, times never decreasing: the
        controller advances its state from the time it was last asked to, with the inputs fed
        since. The same inputs fed at the same times give the same poses.
    """

    inputs: dict

    def feed(self, **values): ...


class Skinned(Protocol):
    """The operation a segmenter declaring ``Capabilities(skin=True)`` offers: ``segment`` with
    the skin of the motion's points (a ``flockkit.mesh.MeshSkin``, one row per point); without
    one (None) it raises ValidationError."""

    def segment(self, motion, rng, *, skin=None): ...


class Guided(Protocol):
    """The operations a behavior declaring ``Capabilities(guide=True)`` offers."""

    def forward(self, initial, steps, rng, *, guide=None): ...

    def backward(self, final, steps, rng, *, guide=None): ...


class GroupGuided(Protocol):
    """The operation a behavior declaring ``Capabilities(group_guide=True)`` offers."""

    def forward(self, initial, steps, rng, *, group_guide=None): ...


class Residuals(Protocol):
    """The operation a behavior declaring ``Capabilities(residuals=True)`` offers."""

    def plausibility_residuals(self, motion, start=0, stop=None): ...


class Coupling(Protocol):
    """The operation a behavior declaring ``Capabilities(coupling=True)`` offers."""

    def plausibility_coupling(self, motion): ...


class SimulationProgress(Protocol):
    """The operations a behavior declaring ``Capabilities(progress=True)`` offers."""

    def forward(self, initial, steps, rng, *, progress=None): ...

    def backward(self, final, steps, rng, *, progress=None): ...


class BuildProgress(Protocol):
    """The operation a builder declaring ``Capabilities(progress=True)`` offers."""

    def build(self, motion, metric, rng, *, progress=None): ...


class LowerBound(Protocol):
    """The operation a metric declaring ``Capabilities(lower_bound=True)`` offers."""

    def lower_bound(self, a, b): ...


class PairsWithin(Protocol):
    """The operation a metric declaring ``Capabilities(pairs_within=True)`` offers."""

    def pairs_within(self, configurations, threshold, *, rows=None): ...


class Pairwise(Protocol):
    """The operation a metric declaring ``Capabilities(pairwise=True)`` offers."""

    def pairwise(self, configurations, pairs=None): ...
