"""A small correct behavior model and one broken variant per behavior check of the kit."""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix

import flockkit
from flockkit import rigid
from flockkit.errors import ValidationError
from flockkit.testing.inputs import recording


class RandomVelocity:
    """Velocity random walk: v[t] = v[t-1] + sigma * noise, x[t+1] = x[t] + v[t] * dt (frame 0 drifts).

    Its plausibility is the Gaussian log density of the inferred noise: a correct, minimal model.
    """

    sigma = 0.05

    def __init__(self, dt=0.1):
        self.dt = dt

    def _steps(self, steps):
        if not isinstance(steps, int) or steps < 0:
            raise ValidationError(f"steps must be an integer >= 0; got {steps!r}")

    def _run(self, x0, v0, steps, rng, guide=None, progress=None, group_guide=None):
        positions = np.empty((steps + 1, *x0.shape))
        positions[0] = x0
        velocity = np.array(v0)
        for t in range(steps):
            if t > 0:
                velocity = velocity + self.sigma * rng.standard_normal(x0.shape)
                for agents, path in group_guide or ():  # half way to the velocity that reaches the path
                    wanted = (path[t + 1] - positions[t, agents].mean(axis=0)) / self.dt
                    velocity[agents] += 0.5 * (wanted - velocity[agents].mean(axis=0))
            positions[t + 1] = positions[t] + velocity * self.dt
            for agent, path in (guide or {}).items():
                positions[t + 1, agent] = path[t + 1]
            velocity = (positions[t + 1] - positions[t]) / self.dt
            if progress is not None:
                progress(t + 1, steps, "simulating")
        return positions

    def forward(self, initial, steps, rng):
        self._steps(steps)
        return flockkit.Motion(positions=self._run(initial.positions, initial.velocities, steps, rng), dt=self.dt)

    def backward(self, final, steps, rng):
        self._steps(steps)
        return flockkit.Motion(positions=self._run(final.positions, -final.velocities, steps, rng)[::-1], dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError(f"window {start}:{stop} outside 0..{motion.n_frames}")
        values = np.zeros(stop - start)
        velocities = np.diff(motion.positions, axis=0) / motion.dt
        for t in range(max(start, 1), min(stop, motion.n_frames - 1)):
            noise = (velocities[t] - velocities[t - 1]) / self.sigma
            values[t - start] = -0.5 * float(np.sum(noise**2)) - noise.size * 0.5 * math.log(2 * math.pi)
        return values


class Declaring(RandomVelocity):
    """RandomVelocity with every optional operation a behavior can declare, done right: guided
    agents, progress reports, its plausibility's reach (frame t reads frames t - 1 .. t + 1) and
    its residuals (the inferred noise)."""

    capabilities = flockkit.Capabilities(
        guide=True, group_guide=True, progress=True, plausibility_reach=1, residuals=True, coupling=True
    )

    def plausibility_coupling(self, motion):
        """Its agents move independently: no residual follows another agent."""
        size = motion.positions.size
        return coo_matrix((size, size))

    def plausibility_residuals(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError(f"window {start}:{stop} outside 0..{motion.n_frames}")
        noise = np.zeros((motion.n_frames, motion.n_agents, motion.dims))
        velocities = np.diff(motion.positions, axis=0) / motion.dt
        noise[1:-1] = (velocities[1:] - velocities[:-1]) / self.sigma
        return noise[start:stop]

    def forward(self, initial, steps, rng, *, guide=None, progress=None, group_guide=None):
        self._steps(steps)
        positions = self._run(initial.positions, initial.velocities, steps, rng, guide, progress, group_guide)
        return flockkit.Motion(positions=positions, dt=self.dt)

    def backward(self, final, steps, rng, *, guide=None, progress=None):
        self._steps(steps)
        reversed_guide = {a: np.asarray(p)[::-1] for a, p in (guide or {}).items()}
        positions = self._run(final.positions, -final.velocities, steps, rng, reversed_guide, progress)
        return flockkit.Motion(positions=positions[::-1], dt=self.dt)


class MissingMethod:
    """Breaks check_interface: no backward at all."""

    forward = RandomVelocity.forward
    log_plausibility = RandomVelocity.log_plausibility


class OffByOneFrames(RandomVelocity):
    def forward(self, initial, steps, rng):
        return super().forward(initial, max(steps - 1, 0), rng)


class BackwardOffByOne(RandomVelocity):
    def backward(self, final, steps, rng):
        return super().backward(final, steps + 1, rng)


class ShiftedStart(RandomVelocity):
    def forward(self, initial, steps, rng):
        motion = super().forward(initial, steps, rng)
        return flockkit.Motion(positions=motion.positions + 1e-3, dt=motion.dt)


class BackwardEndsElsewhere(RandomVelocity):
    def backward(self, final, steps, rng):
        return super().forward(final, steps, rng)


class BallisticBackward(RandomVelocity):
    """backward draws a straight line at the final velocities: it ends where it should, but it is
    no simulation."""

    def backward(self, final, steps, rng):
        self._steps(steps)
        before = np.arange(steps, -1, -1)[:, None, None] * self.dt
        return flockkit.Motion(positions=final.positions - before * final.velocities, dt=self.dt)


class GlobalRandomness(RandomVelocity):
    """Ignores rng and draws from a fresh, unseeded generator."""

    def forward(self, initial, steps, rng):
        return super().forward(initial, steps, np.random.default_rng())


class MutatesInput(RandomVelocity):
    def forward(self, initial, steps, rng):
        initial.positions.setflags(write=True)
        initial.positions[0, 0] += 1.0
        return super().forward(initial, steps, rng)


class AcceptsNegativeSteps(RandomVelocity):
    def _steps(self, steps):
        pass

    def forward(self, initial, steps, rng):
        return super().forward(initial, max(steps, 0), rng)

    def backward(self, final, steps, rng):
        return super().backward(final, max(steps, 0), rng)


class NonFinitePlausibility(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        values = super().log_plausibility(motion, start, stop)
        return np.where(np.arange(start, start + len(values)) == 1, -np.inf, values)


class ReturnsAList(RandomVelocity):
    """Its plausibility comes back as a Python list of floats, not an array."""

    def log_plausibility(self, motion, start=0, stop=None):
        return [float(v) for v in super().log_plausibility(motion, start, stop)]


class ScoresAtItsOwnDt(RandomVelocity):
    """Infers velocities with the model's dt, whatever motion.dt says."""

    def log_plausibility(self, motion, start=0, stop=None):
        stepped = flockkit.Motion(positions=motion.positions, dt=self.dt, channels=motion.channels)
        return super().log_plausibility(stepped, start, stop)


class PrefersNoise(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        return -super().log_plausibility(motion, start, stop)


class WindowIgnored(RandomVelocity):
    """Returns the right length but always scores from frame 0."""

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError("bad window")
        return super().log_plausibility(motion)[: stop - start]


class WindowUnchecked(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        full = super().log_plausibility(motion)
        return np.resize(full[max(start, 0) : stop], max(stop - start, 0))


class IgnoresGuide(Declaring):
    def forward(self, initial, steps, rng, *, guide=None, progress=None):
        return super().forward(initial, steps, rng, progress=progress)


class IgnoresGroupGuide(Declaring):
    def forward(self, initial, steps, rng, *, guide=None, progress=None, group_guide=None):
        return super().forward(initial, steps, rng, guide=guide, progress=progress)


class SilentProgress(Declaring):
    def forward(self, initial, steps, rng, *, guide=None, progress=None):
        return super().forward(initial, steps, rng, guide=guide)


class ReachTooShort(Declaring):
    """Declares a reach of 1, but scores each frame with its neighbors' velocity changes too."""

    def log_plausibility(self, motion, start=0, stop=None):
        full = RandomVelocity.log_plausibility(self, motion)
        smeared = full + np.roll(full, 1) + np.roll(full, -1)
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError(f"window {start}:{stop} outside 0..{motion.n_frames}")
        return smeared[start:stop]


class ResidualsOffScale(Declaring):
    """Residuals that are the noise over twice sigma: their squares are not what it scores."""

    def plausibility_residuals(self, motion, start=0, stop=None):
        return super().plausibility_residuals(motion, start, stop) / 2


class CouplingInvented(Declaring):
    """Says agent 0's residuals at frame 2 follow agent 1's position there; they do not."""

    def plausibility_coupling(self, motion):
        size = motion.positions.size
        n, d = motion.n_agents, motion.dims
        rows, columns = (2 * n + 0) * d + np.arange(d), (2 * n + 1) * d + np.arange(d)
        return coo_matrix((np.ones(d), (rows, columns)), shape=(size, size))


class CrowdingByDistance(RandomVelocity):
    """Pushes each agent away from its nearest neighbour by the inverse of their distance: fine on
    random flocks, NaN where two agents share a spot."""

    def forward(self, initial, steps, rng):
        motion = super().forward(initial, steps, rng)
        if initial.n_agents < 2:
            return motion
        positions = np.array(motion.positions)
        gaps = positions[:, :, None, :] - positions[:, None, :, :]
        distance = np.linalg.norm(gaps, axis=-1)
        distance[:, range(initial.n_agents), range(initial.n_agents)] = np.inf
        nearest = np.argmin(distance, axis=2)
        away = np.take_along_axis(gaps, nearest[..., None, None], axis=2)[:, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            push = away / np.min(distance, axis=2)[..., None] ** 2
        positions[1:] += 1e-3 * push[1:]
        return flockkit.Motion(positions=positions, dt=self.dt)


# check name -> a fake that breaks exactly that check
BROKEN = {
    "check_interface": MissingMethod,
    "check_forward_shape": OffByOneFrames,
    "check_backward_shape": BackwardOffByOne,
    "check_forward_starts_at_initial": ShiftedStart,
    "check_backward_ends_at_final": BackwardEndsElsewhere,
    "check_backward_is_a_simulation": BallisticBackward,
    "check_deterministic": GlobalRandomness,
    "check_inputs_unchanged": MutatesInput,
    "check_rejects_negative_steps": AcceptsNegativeSteps,
    "check_log_plausibility_finite": NonFinitePlausibility,
    "check_log_plausibility_at_motion_dt": ScoresAtItsOwnDt,
    "check_degenerate_flocks": CrowdingByDistance,
    "check_log_plausibility_prefers_forward": PrefersNoise,
    "check_log_plausibility_window": WindowIgnored,
    "check_rejects_bad_window": WindowUnchecked,
    "check_guide": IgnoresGuide,
    "check_group_guide": IgnoresGroupGuide,
    "check_progress": SilentProgress,
    "check_plausibility_reach": ReachTooShort,
    "check_residuals": ResidualsOffScale,
    "check_coupling": CouplingInvented,
}


# -- metrics: the built-in is the correct base; each fake breaks one check ------------------

from flockkit_icp import IcpHungarian  # noqa: E402


class _Wrapped:
    """Delegates to the built-in metric; subclasses change one thing."""

    capabilities = flockkit.Capabilities(lower_bound=True, pairs_within=True, pairwise=True)

    def __init__(self):
        self.inner = IcpHungarian()

    def compare(self, a, b):
        return self.inner.compare(a, b)

    def lower_bound(self, a, b):
        return self.inner.lower_bound(a, b)

    def pairwise(self, configurations, pairs=None):
        return self.inner.pairwise(configurations, pairs)

    def pairs_within(self, configurations, threshold, *, rows=None):
        return self.inner.pairs_within(configurations, threshold, rows=rows)

    @staticmethod
    def _with(found, **changes):
        fields = {
            "distance": found.distance,
            "assignment": found.assignment,
            "rotation": found.rotation,
            "translation": found.translation,
        }
        fields.update(changes)
        return flockkit.Alignment(**fields)


class NoCompare:
    def lower_bound(self, a, b):
        return 0.0


class ReturnsTuple(_Wrapped):
    def compare(self, a, b):
        found = super().compare(a, b)
        return found.distance, found.assignment


class OffsetDistance(_Wrapped):
    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=found.distance + 1.0)


class IgnoresRotation(_Wrapped):
    """Matches centered positions without rotating: not rotation-invariant."""

    def compare(self, a, b):
        from scipy.optimize import linear_sum_assignment
        from scipy.spatial.distance import cdist

        pa, pb = a.positions - a.center_of_mass(), b.positions - b.center_of_mass()
        cost = cdist(pa, pb, "sqeuclidean")
        _, assignment = linear_sum_assignment(cost)
        return flockkit.Alignment(
            distance=cost[np.arange(len(pa)), assignment].mean(),
            assignment=assignment,
            rotation=np.eye(a.dims),
            translation=a.center_of_mass() - b.center_of_mass(),
        )


class UnderReports(_Wrapped):
    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=found.distance / 10)


class LooseBound(_Wrapped):
    def lower_bound(self, a, b):
        return 2 * self.inner.compare(a, b).distance + 1.0


class PrunesTooMuch(_Wrapped):
    """Leaves out the first pair, two configurations a few steps apart (so within the threshold)."""

    def pairs_within(self, configurations, threshold, *, rows=None):
        return self.inner.pairs_within(configurations, threshold, rows=rows)[1:]


class WrongPairwise(_Wrapped):
    """Distances for the pairs in column-major order instead of the asked order."""

    def pairwise(self, configurations, pairs=None):
        return np.asarray(self.inner.pairwise(configurations, pairs))[::-1]


class Jittery(_Wrapped):
    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=found.distance + np.random.default_rng().random() * 1e-6)


class MutatesConfiguration(_Wrapped):
    def compare(self, a, b):
        b.positions.setflags(write=True)
        b.positions[0] += 1.0
        return super().compare(a, b)


class Truncates(_Wrapped):
    def compare(self, a, b):
        n, d = min(a.n_agents, b.n_agents), min(a.dims, b.dims)
        cut = [flockkit.Configuration(positions=c.positions[:n, :d], velocities=c.velocities[:n, :d]) for c in (a, b)]
        return super().compare(*cut)


class Asymmetric(_Wrapped):
    """Counts the distance three times over when `a` lies left of `b`."""

    def compare(self, a, b):
        found = super().compare(a, b)
        heavier = a.center_of_mass()[0] < b.center_of_mass()[0]
        return self._with(found, distance=found.distance * (3.0 if heavier else 1.0))


class SquaredAgain(_Wrapped):
    """The residual plus ten times its square: invariant, symmetric, above the residual, but it
    grows faster than a squared distance."""

    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=found.distance + 10 * found.distance**2)


class RootMeanSquare(_Wrapped):
    """The root of the mean squared residual: invariant, symmetric, zero for copies, not a mean of squares."""

    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=float(np.sqrt(found.distance)))


class SumOfSquares(_Wrapped):
    """The residual summed over agents instead of averaged."""

    def compare(self, a, b):
        found = super().compare(a, b)
        return self._with(found, distance=found.distance * a.n_agents)


class TieBreaking:
    """Matches agents in the order of their distance to the centre of mass (ties by index), then
    rotates by Kabsch: exact for rigid copies of configurations without ties, wrong for a square."""

    capabilities = flockkit.Capabilities()

    def compare(self, a, b):
        if (a.n_agents, a.dims) != (b.n_agents, b.dims):
            raise ValidationError("configurations of different sizes")
        pa, pb = a.positions - a.center_of_mass(), b.positions - b.center_of_mass()
        order_a = np.argsort(np.linalg.norm(pa, axis=1), kind="stable")
        order_b = np.argsort(np.linalg.norm(pb, axis=1), kind="stable")
        assignment = np.empty(a.n_agents, dtype=int)
        assignment[order_a] = order_b
        rotation = rigid.kabsch(pa, pb[assignment])
        placed = pb[assignment] @ rotation.T
        return flockkit.Alignment(
            distance=float(np.mean(np.sum((pa - placed) ** 2, axis=1))),
            assignment=assignment,
            rotation=rotation,
            translation=a.center_of_mass() - rotation @ b.center_of_mass(),
        )


BROKEN_METRICS = {
    "check_interface": NoCompare,
    "check_compare_returns_alignment": ReturnsTuple,
    "check_identical_is_zero": OffsetDistance,
    "check_rigid_and_permutation_invariant": IgnoresRotation,
    "check_distance_covers_alignment": UnderReports,
    "check_distance_is_a_mean_of_squares": SumOfSquares,
    "check_symmetric": Asymmetric,
    "check_relaxed_triangle": SquaredAgain,
    "check_degenerate_configurations": TieBreaking,
    "check_lower_bound": LooseBound,
    "check_pairs_within": PrunesTooMuch,
    "check_pairwise": WrongPairwise,
    "check_deterministic": Jittery,
    "check_inputs_unchanged": MutatesConfiguration,
    "check_rejects_mismatched_sizes": Truncates,
}
BROKEN_BY_KIND = {"behavior": BROKEN, "metric": BROKEN_METRICS}


# -- builders: the built-in kovar is the correct base ---------------------------------------

import attrs  # noqa: E402
from flockkit_kovar import Kovar  # noqa: E402
from flockkit_walks import RandomWalk  # noqa: E402


class _KovarBased:
    def __init__(self):
        self.inner = Kovar()

    def build(self, motion, metric, rng):
        return self.inner.build(motion, metric, rng)


class SilentBuilder(_KovarBased):
    """Declares progress and takes the keyword, but never reports."""

    capabilities = flockkit.Capabilities(progress=True)

    def build(self, motion, metric, rng, *, progress=None):
        return super().build(motion, metric, rng)


class NoBuild:
    def make(self, motion, metric, rng):
        return None


class ReturnsNodes(_KovarBased):
    def build(self, motion, metric, rng):
        return super().build(motion, metric, rng).nodes


class DeadEnds(_KovarBased):
    def build(self, motion, metric, rng):
        graph = super().build(motion, metric, rng)
        last = len(graph.nodes) - 1
        return attrs.evolve(graph, transitions=[t for t in graph.transitions if t.source != last])


class OverclaimsAlignment(_KovarBased):
    def build(self, motion, metric, rng):
        graph = super().build(motion, metric, rng)
        return attrs.evolve(
            graph,
            transitions=[
                attrs.evolve(t, alignment=_Wrapped._with(t.alignment, distance=0.0)) for t in graph.transitions
            ],
        )


class RandomSubset(_KovarBased):
    """Drops a different transition on every call (as a build depending on global state would)."""

    calls = 0

    def build(self, motion, metric, rng):
        graph = super().build(motion, metric, rng)
        RandomSubset.calls += 1
        drop = RandomSubset.calls % len(graph.transitions)
        return attrs.evolve(graph, transitions=[t for k, t in enumerate(graph.transitions) if k != drop])


class MutatesMotion(_KovarBased):
    def build(self, motion, metric, rng):
        motion.positions.setflags(write=True)
        motion.positions[0] += 1.0
        return super().build(motion, metric, rng)


class AcceptsArrays(_KovarBased):
    def build(self, motion, metric, rng):
        if not isinstance(motion, flockkit.Motion):
            motion = recording(n_agents=6, seconds=12.0, seed=11)
        return super().build(motion, metric, rng)


BROKEN_BUILDERS = {
    "check_interface": NoBuild,
    "check_build_returns_graph": ReturnsNodes,
    "check_strongly_connected": DeadEnds,
    "check_transitions_align": OverclaimsAlignment,
    "check_deterministic": RandomSubset,
    "check_inputs_unchanged": MutatesMotion,
    "check_rejects_bad_motion": AcceptsArrays,
    "check_progress": SilentBuilder,
}


# -- walks: the built-in random walk is the correct base ------------------------------------


class NoWalk:
    def stroll(self, graph, rng, duration):
        return None


class HalfWalk:
    def walk(self, graph, rng, duration):
        return (
            RandomWalk(start=0).walk(graph, rng, max(duration / 2, 0.1))
            if duration > 0
            else RandomWalk().walk(graph, rng, duration)
        )


class UnseededWalk:
    def walk(self, graph, rng, duration):
        return RandomWalk().walk(graph, np.random.default_rng(), duration)


class ClampsDuration:
    def walk(self, graph, rng, duration):
        return RandomWalk().walk(graph, rng, max(duration, 1.0))


class TabuWalk:
    """Random edges, never one taken in the last `tenure` edges: when every allowed edge is tabu it
    raises (`patient=False`) or keeps drawing for ever (`patient=True`)."""

    def __init__(self, tenure=4, patient=False):
        self.tenure, self.patient = tenure, patient

    def walk(self, graph, rng, duration):
        if not duration > 0:
            raise ValidationError(f"duration must be > 0; got {duration}")
        node, since, played, edges = 0, math.inf, 0.0, []
        while played < duration:
            options = [e for e in graph.allowed_edges(node, since) if e not in edges[-self.tenure :]]
            if not options:
                if self.patient:
                    continue
                raise ValidationError("every allowed edge is tabu")
            edge = options[int(rng.integers(len(options)))]
            frames = graph.clips[edge[1]].stop - graph.clips[edge[1]].start if edge[0] == "clip" else 0
            edges.append(edge)
            played += frames * graph.motion.dt
            since = since + frames if edge[0] == "clip" else 0
            node = graph.edge_target(edge)
        return flockkit.Walk(start=0, edges=edges)


BROKEN_WALKS = {
    "check_interface": NoWalk,
    "check_walk_covers_duration": HalfWalk,
    "check_walks_a_single_loop": TabuWalk,
    "check_deterministic": UnseededWalk,
    "check_rejects_bad_duration": ClampsDuration,
}
BROKEN_BY_KIND.update({"builder": BROKEN_BUILDERS, "walk": BROKEN_WALKS})


# -- objectives: the built-in com term is the correct base ----------------------------------

from flockkit_objectives import ComTerm  # noqa: E402


class NoLogTerms:
    def score(self, motion, problem, start=0, stop=None):
        return 0.0


class NanTerms(ComTerm):
    def log_terms(self, motion, problem, start=0, stop=None):
        terms = super().log_terms(motion, problem, start, stop)
        return np.where(terms != 0, np.nan, terms)


class WindowFromZero(ComTerm):
    """Ignores `start`: returns the first stop - start frames."""

    def log_terms(self, motion, problem, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        return (
            super().log_terms(motion, problem, 0, max(stop - start, 0))
            if 0 <= start <= stop <= motion.n_frames
            else super().log_terms(motion, problem, start, stop)
        )


class MutatesMotionTerms(ComTerm):
    def log_terms(self, motion, problem, start=0, stop=None):
        motion.positions.setflags(write=True)
        motion.positions[0, 0] += 1.0
        return super().log_terms(motion, problem, start, stop)


class ClipsWindow(ComTerm):
    """Clips a bad window into the motion, and pads a short motion, instead of raising."""

    def log_terms(self, motion, problem, start=0, stop=None):
        stop = motion.n_frames if stop is None else min(stop, motion.n_frames)
        start = min(start, stop)
        if motion.n_agents != problem.n_agents:
            return np.zeros(stop - start)
        return super().log_terms(motion, problem, start, stop)


BROKEN_OBJECTIVES = {
    "check_interface": NoLogTerms,
    "check_log_terms_per_frame": NanTerms,
    "check_window_is_a_slice": WindowFromZero,
    "check_inputs_unchanged": MutatesMotionTerms,
    "check_rejects_bad_window": ClipsWindow,
}
BROKEN_BY_KIND["objective"] = BROKEN_OBJECTIVES


# -- proposals: the built-in velocity move is the correct base -------------------------------

from flockkit_proposals import Retime  # noqa: E402


class NoPropose:
    def suggest(self, current, context, rng):
        return None


class DropsFrames(Retime):
    def propose(self, current, context, rng):
        proposal = super().propose(current, context, rng)
        if proposal is None:
            return None
        return flockkit.Proposal(
            motion=flockkit.Motion(positions=proposal.motion.positions[:-1], dt=current.dt),
            start=proposal.start,
            stop=proposal.stop,
            agents=proposal.agents,
        )


class MovesPinned(Retime):
    """Shifts every agent at every frame a little (and says so): breaks point constraints."""

    def propose(self, current, context, rng):
        return flockkit.Proposal(
            motion=flockkit.Motion(positions=current.positions + 1e-3, dt=current.dt),
            start=0,
            stop=current.n_frames,
            agents=tuple(range(current.n_agents)),
        )


class RestartsFree(Retime):
    """Speeds up the free agents' start (frame 1), which no term scores, and says so."""

    def propose(self, current, context, rng):
        positions = current.positions.copy()
        free = np.flatnonzero(~context.pinned[1]) if not context.pinned[1].all() else np.arange(current.n_agents)
        positions[1, free] += 0.5
        return flockkit.Proposal(motion=flockkit.Motion(positions=positions, dt=current.dt), start=1, stop=2,
                                 agents=tuple(int(a) for a in free))  # fmt: skip


class UnderReports(Retime):
    def propose(self, current, context, rng):
        proposal = super().propose(current, context, rng)
        if proposal is None:
            return None
        return flockkit.Proposal(
            motion=proposal.motion, start=proposal.start, stop=proposal.start + 1, agents=proposal.agents
        )


class MutatesCurrent(Retime):
    def propose(self, current, context, rng):
        current.positions.setflags(write=True)
        current.positions[0, 0, 0] += 1.0
        return super().propose(current, context, rng)


BROKEN_BY_KIND["proposal"] = {
    "check_interface": NoPropose,
    "check_returns_proposals": DropsFrames,
    "check_keeps_point_constraints": MovesPinned,
    "check_leaves_held_frames": RestartsFree,
    "check_reports_changes": UnderReports,
    "check_input_unchanged": MutatesCurrent,
}


# -- segmenters: the built-in ica-kmeans is the correct base ----------------------------------

from flockkit_ica import IcaKmeans  # noqa: E402

import flockkit  # noqa: E402


class NoSegment:
    def split(self, motion, rng):
        return None


class DropsAPoint(IcaKmeans):
    def segment(self, motion, rng):
        found = super().segment(motion, rng)
        return flockkit.Segmentation(labels=found.labels[:-1], n_parts=found.n_parts)


class ByPosition(IcaKmeans):
    """Splits by where points are, not how they move: left and right of the first coordinate's median."""

    def segment(self, motion, rng):
        if not isinstance(motion, flockkit.Motion):
            raise flockkit.errors.ValidationError("not a Motion")
        x = motion.positions[0, :, 0]
        return flockkit.Segmentation(labels=(x > np.median(x)).astype(int), n_parts=2)


class UnseededSegment(IcaKmeans):
    """Names its parts differently on every call (state kept between calls, not from `rng`)."""

    calls = 0

    def segment(self, motion, rng):
        found = super().segment(motion, rng)
        UnseededSegment.calls += 1
        names = np.roll(np.arange(found.n_parts), UnseededSegment.calls)
        return flockkit.Segmentation(labels=names[found.labels], n_parts=found.n_parts)


class OrderDependent(IcaKmeans):
    """Splits the first half of the points from the second, whatever they do."""

    def segment(self, motion, rng):
        super().segment(motion, rng)
        return flockkit.Segmentation(labels=(np.arange(motion.n_agents) >= motion.n_agents // 2).astype(int), n_parts=2)


class MutatesMotionSegment(IcaKmeans):
    def segment(self, motion, rng):
        motion.positions.setflags(write=True)
        motion.positions[0, 0] += 1.0
        return super().segment(motion, rng)


class AcceptsArrays(IcaKmeans):
    def segment(self, motion, rng):
        if not isinstance(motion, flockkit.Motion):
            motion = flockkit.Motion(positions=motion, dt=0.1)
        return super().segment(motion, rng)


class SplitsBySide(IcaKmeans):
    """Cuts a group that moves as one into its left and right halves."""

    def segment(self, motion, rng):
        found = super().segment(motion, rng)
        if found.n_parts > 1 or motion.n_agents < 2:
            return found
        left = motion.positions[0, :, 0] < np.median(motion.positions[0, :, 0])
        return flockkit.Segmentation(labels=left.astype(int), n_parts=2) if 0 < left.sum() < motion.n_agents else found


class MergesMovingParts(IcaKmeans):
    """Keeps still points apart but puts every moving point in one part."""

    def segment(self, motion, rng):
        super().segment(motion, rng)
        moving = np.ptp(motion.positions, axis=0).max(axis=1) > 0
        labels = np.unique(moving, return_inverse=True)[1].ravel()
        return flockkit.Segmentation(labels=labels, n_parts=int(labels.max()) + 1)


class CutsByReach(IcaKmeans):
    """Splits each part whose points travel different distances (points far from a turning
    centre travel more) into the nearer and the farther half."""

    def segment(self, motion, rng):
        found = super().segment(motion, rng)
        travel = np.linalg.norm(np.diff(motion.positions, axis=0), axis=2).sum(axis=0)
        labels = found.labels.copy()
        for part in found.parts():
            far = travel[part] > np.median(travel[part])
            if np.ptp(travel[part]) > 1e-9 * max(travel[part].max(), 1.0) and 0 < far.sum() < len(part):
                labels[part[far]] = labels.max() + 1
        return flockkit.Segmentation(labels=np.unique(labels, return_inverse=True)[1].ravel(),
                                     n_parts=len(np.unique(labels)))  # fmt: skip


BROKEN_BY_KIND["segmenter"] = {
    "check_interface": NoSegment,
    "check_labels_cover_every_point": DropsAPoint,
    "check_still_points_apart_from_moving_ones": ByPosition,
    "check_independent_groups_apart": MergesMovingParts,
    "check_rigid_body_is_one_part": CutsByReach,
    "check_identical_motion_is_one_part": SplitsBySide,
    "check_deterministic": UnseededSegment,
    "check_order_of_points_does_not_matter": OrderDependent,
    "check_inputs_unchanged": MutatesMotionSegment,
    "check_rejects_bad_motion": AcceptsArrays,
}

# segmenters that need a skin: the built-in skin-parts is the correct base

from flockkit_skinparts import SkinParts  # noqa: E402


class IgnoresBadSkin(SkinParts):
    """Segments without a skin, or with one that does not fit, as one part instead of refusing."""

    def segment(self, motion, rng, *, skin=None):
        if skin is None or skin.n_vertices != motion.n_agents:
            return flockkit.Segmentation(labels=np.zeros(motion.n_agents, dtype=int), n_parts=1)
        return super().segment(motion, rng, skin=skin)


class MergesEveryJoint(SkinParts):
    """Merges joints along the skeleton whatever their motion: one part."""

    def __init__(self):
        super().__init__(n_parts=1)


BROKEN_BY_KIND["segmenter"].update(
    {"check_rejects_missing_or_unfitting_skin": IgnoresBadSkin, "check_skinned_limbs_found": MergesEveryJoint}
)


# -- controllers: the built-in clip player is the correct base ------------------------------

from flockkit_controllers import ClipPlayer  # noqa: E402

from flockkit.crowd import Pose  # noqa: E402
from flockkit.testing import inputs  # noqa: E402


class Walker(ClipPlayer):
    def __init__(self, **params):
        super().__init__(clip=inputs.walker(), **params)


class NoEvents:
    skeleton = inputs.walker().skeleton

    def pose(self, times):
        return Walker().pose(times)


class DropsAJoint(Walker):
    def pose(self, times):
        pose = super().pose(times)
        return Pose(rotations=pose.rotations[:, 1:], translations=pose.translations[:, 1:])


class RemembersTheLastCall(Walker):
    """Plays on from wherever the previous call stopped: a pose depends on the calls before."""

    def pose(self, times):
        offset = getattr(self, "_offset", 0.0)
        object.__setattr__(self, "_offset", offset + 0.1)
        return super().pose(np.asarray(times) + offset)


class RepeatsEventsAtCuts(Walker):
    """Reaches a quarter second back before each window: an event just before a cut comes twice."""

    def events(self, start, stop):
        return super().events(max(start - 0.25, 0.0), stop)


class AcceptsNegativeTimes(Walker):
    def pose(self, times):
        return self.clip.sample(np.abs(np.atleast_1d(np.asarray(times, dtype=float))))


class SortsTimesInPlace(Walker):
    def pose(self, times):
        if isinstance(times, np.ndarray):
            times.sort()
        return super().pose(times)


class Strider(ClipPlayer):
    """Plays the kit's strider in place with its root motion taken out: a correct root-motion source."""

    def __init__(self, **params):
        from flockkit.crowd import extract_root_motion

        super().__init__(clip=extract_root_motion(inputs.strider()), **params)


class RootMotionOffTheGround(Strider):
    """Lifts its root along the up axis as it goes."""

    def root_motion(self, times):
        found = super().root_motion(times)
        found[:, 2] += 0.1 * np.asarray(times)
        return found


class RootMotionRemembersTheLastCall(Strider):
    def root_motion(self, times):
        offset = getattr(self, "_root_offset", 0.0)
        object.__setattr__(self, "_root_offset", offset + 0.1)
        return super().root_motion(times) + offset


class RootMotionWrapsEachLoop(Strider):
    """Gives the root's motion within the current loop only: each loop jumps back to the start."""

    def root_motion(self, times):
        t = np.atleast_1d(np.asarray(times, dtype=float))
        return super().root_motion(np.mod(t, self.clip.duration))


class BatchIgnoresRate(Walker):
    """Batches as if every player ran at its clip's own speed."""

    def __init__(self, **params):
        super().__init__(rate=1.5, **params)

    def batch(self, controllers):
        return ClipPlayer.batch(self, [ClipPlayer(clip=c.clip) for c in controllers])


from flockkit_controllers import Locomotion  # noqa: E402


class Locomotor(Locomotion):
    """The built-in live controller on the kit's walker: idle (its first frame held) and walking."""

    def __init__(self, **params):
        walker = inputs.walker()
        idle = walker.resampled(walker.fps)
        idle = type(walker)(skeleton=walker.skeleton, fps=walker.fps, rotations=idle.rotations[:1],
                            translations=idle.translations[:1], name="idle")  # fmt: skip
        super().__init__(clips=(idle, walker), speeds=(0.0, 1.4), **params)


class FedInputsOneFrameLate(Locomotor):
    """Shows what was fed only from the frame after."""

    def feed(self, **values):
        waiting = dict(getattr(self, "_waiting", {}))
        object.__setattr__(self, "_waiting", values)
        if waiting:
            super().feed(**waiting)


class RandomPhase(Locomotor):
    """Starts each pose at a random phase: the same inputs do not give the same poses."""

    def pose(self, times):
        self._state["phase"] = float(np.random.default_rng().random())
        return super().pose(times)


class AcceptsAnyInput(Locomotor):
    def feed(self, **values):
        known = {k: v for k, v in values.items() if k in self.inputs and np.isfinite(v) and v >= self.inputs[k][0]}
        super().feed(**known)


BROKEN_BY_KIND["controller"] = {
    "check_batch_equals_pose": BatchIgnoresRate,
    "check_live_input_shows_in_the_next_pose": FedInputsOneFrameLate,
    "check_live_same_inputs_same_poses": RandomPhase,
    "check_live_rejects_bad_inputs": AcceptsAnyInput,
    "check_interface": type("NoPose", (), {"events": lambda self, a, b: []}),
    "check_poses_fit_the_skeleton": DropsAJoint,
    "check_pose_is_a_function_of_time": RemembersTheLastCall,
    "check_events_split_by_windows": RepeatsEventsAtCuts,
    "check_rejects_bad_times": AcceptsNegativeTimes,
    "check_times_unchanged": SortsTimesInPlace,
    "check_root_motion_on_the_ground": RootMotionOffTheGround,
    "check_root_motion_is_a_function_of_time": RootMotionRemembersTheLastCall,
    "check_root_motion_is_continuous": RootMotionWrapsEachLoop,
}
