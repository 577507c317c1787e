"""Kovar-style motion-graph construction (paper 000 section 4.3).

1. Candidate frames every `candidate_interval` seconds (leaving room for a blend at the end).
2. The difference matrix E(t_i, t_j) = metric.compare(configuration(t_i), configuration(t_j)).
3. Transitions at local minima of E (over its 8 neighbors, the diagonal excluded) at least
   `min_gap` seconds apart and at most the threshold; both directions of each minimum.
4. ``flockkit.MotionGraph.assemble``: clips between transition frames, dead ends trimmed.
5. Turns (``flockkit.graphs.turns``): every `turn_interval` seconds of the kept recording, the same
   motion rotated by +-`turn_angle` degrees about the group's center of mass, so that walks can
   steer a group whose recording barely turns (a default boids flock turns under 5 degrees a
   second; a region walk needs more). ``turn_angle=0`` builds the paper's graph without them.

Threshold. Given `threshold` it is absolute. Otherwise it is adaptive: with `wanted` =
max(`min_transitions`, `transitions_per_minute` per minute of recording), the lowest `wanted` local
minima are taken, and while fewer than `wanted` transitions survive the trimming of dead ends, the
next lowest are added, as many as are missing. The threshold is the value of the last one taken
(at most the group's mean squared radius, its mean squared distance to the center of mass
averaged over candidates; if even that is not enough, every minimum under it is taken). Like the
paper's rule, the graph grows with the recording, and its density is what was asked for whatever
the units. With `per_second`, the paper's rule is used instead: the lowest
``ceil(per_second * duration)`` local minima, whatever their values.

Pruning. With a threshold, E is only computed for the pairs the metric's
``pairs_within(configurations, threshold)`` lists (or, for a metric with only ``lower_bound``,
where that bound is at most the threshold). A cell left out has E > threshold, so it can
neither be a transition nor keep a computed cell under the threshold from being a local minimum.
The adaptive rule is decided by probing: the minima under a probe threshold are exactly the
lowest minima of the full matrix, so the probe goes up until they decide the rule. The first
probe comes from thin strips of rows (one in the middle of each of equal parts of the recording;
as few strips as should hold 8 of the minima needed, at least 3, at most half the rows), probed
from 0.04 times the mean squared radius upwards, doubling: the value under which the strips'
minima, scaled to the whole matrix, number twice those wanted. It usually decides at once; if
not, the probe goes up by a tenth at a time. Rows are never listed twice at the same probe, and
cells nearer the diagonal than any transition's neighbors are never computed. ``prune=True`` and
``prune=False`` give the identical graph. The `per_second` rule needs every value and never
prunes.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

# Where the strips' probing starts, as a fraction of the group's mean squared radius: on boids
# recordings (bench/build.py) the strips decided at 0.04 (100 agents) or 0.08 of it (20 agents,
# 1 000 to 18 000 candidates), so starting at 0.04 skips a doubling that never decided (5-10% of
# a build, the same evaluations; from 0.02 until 2026-12-02).
_FIRST_PROBE = 0.04
# The strips are made many enough to be expected to hold this many of the minima their estimate
# needs. A 60 s recording (30 transitions wanted) with four strips expected to hold 3: at 100 boids
# the estimate fell 6% short and every row was listed twice (21.1 s); at 20 it overshot (2.9 s).
# With twelve strips (8): 13.1-14.5 and 1.1-1.2 s, 50 boids 7.5 -> 4.9-5.7 s; 5, 6, 7 and 10
# were each worse on one of these. Longer recordings need only 3 (4 003 candidates: 23.7 s
# against 35.8 with a tenth of the rows in strips; bench/README.md).
_STRIP_MINIMA = 8


@attrs.frozen(kw_only=True)
class Kovar:
    """Parameters
    ----------
    candidate_interval : float
        Seconds between candidate frames (rounded to whole frames, at least one).
    min_gap : float
        Seconds at least between the two frames of a transition.
    threshold : float, optional
        Absolute threshold on E; None: adaptive (see the module docstring).
    min_transitions, transitions_per_minute : int, float
        The adaptive threshold keeps max(min_transitions, transitions_per_minute per minute of
        recording) transitions after dead-end trimming (see the module docstring).
    per_second : float, optional
        Use the paper's rule instead: the lowest ceil(per_second * duration) local minima.
    blend_time : float
        Seconds over which synthesis blends across a transition.
    turn_angle : float
        Degrees of each turn (0: no turns). A turn is played over `blend_time`, so 15 degrees over
        2 s turns at most 7.5 degrees a second. The formation turns with the heading, as in any
        rigid turn, so an agent r from the center moves up to about 1.5 r times the turn rate
        faster for a moment (the default keeps synthesized steps within 1.3 times the recording's
        largest on boids); the blend shrinks the group by at most 1 - cos(turn_angle / 2) half way
        (0.9% at 15 degrees).
    turn_interval : float
        Seconds between the frames that offer turns.
    prune : bool
        Skip exact evaluations the metric's declared ``pairs_within`` (or ``lower_bound``) rules out.
    bridges : bool
        Add solver-made bridges (``flockkit.graphs.bridge`` along ``flockkit.graphs.bridge_plan``):
        the recording's own change of formation every `bridge_seconds`, turned by +-`bridge_turn`
        degrees (straight where a turn is refused), from the recording's end on; they join the
        dead ends that trimming drops (with every transition found there) and give region walks
        turns the recording lacks. Each is solved with `bridge_behavior` and refused below
        `bridge_plausibility` (log plausibility per agent-step).
    n_jobs : int, optional
        joblib workers for the difference matrix (-1: all cores; None: what
        ``joblib.parallel_config`` says, else 1); any joblib backend runs them (``flockkit.parallel``).
    """

    candidate_interval: float = validate.parameter("kovar", default=0.2, minimum=0, strict=True)
    min_gap: float = validate.parameter("kovar", default=1.0, minimum=0)
    threshold: float | None = validate.parameter("kovar", default=None, minimum=0, strict=True, optional=True)
    min_transitions: int = validate.parameter("kovar", default=30, kind="integer", minimum=1)
    transitions_per_minute: float = validate.parameter("kovar", default=20.0, minimum=0)
    per_second: float | None = validate.parameter("kovar", default=None, minimum=0, strict=True, optional=True)
    blend_time: float = validate.parameter("kovar", default=2.0, minimum=0)
    turn_angle: float = validate.parameter("kovar", default=15.0, minimum=0, maximum=90)
    turn_interval: float = validate.parameter("kovar", default=2.0, minimum=0, strict=True)
    prune: bool = validate.parameter("kovar", default=True, kind="flag")
    bridges: bool = validate.parameter("kovar", default=False, kind="flag")
    bridge_seconds: float = validate.parameter("kovar", default=6.0, minimum=0, strict=True)
    bridge_turn: float = validate.parameter("kovar", default=30.0, minimum=0, maximum=90)
    bridge_plausibility: float = validate.parameter("kovar", default=flockkit.graphs.BRIDGE_PLAUSIBILITY)
    bridge_behavior: object = attrs.field(default="boids")
    n_jobs: int | None = attrs.field(default=None)

    capabilities = flockkit.Capabilities(progress=True)

    def __attrs_post_init__(self):
        if self.n_jobs is not None and validate.integer(self.n_jobs, "kovar parameter n_jobs") == 0:
            raise ValidationError("kovar parameter n_jobs must be None or a non-zero integer; got 0")

    def build(
        self, motion: flockkit.Motion, metric, rng: np.random.Generator, *, progress=None
    ) -> flockkit.MotionGraph:
        """The motion graph of `motion` under `metric` (deterministic for a seeded `rng`, which only
        bridges use).
        `progress(done, total, stage)` is called as pairs are bounded and distances computed."""
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"kovar: motion must be a flockkit.Motion; got {type(motion).__name__}")
        stride = max(1, round(self.candidate_interval / motion.dt))
        blend = round(self.blend_time / motion.dt)
        gap = math.ceil(self.min_gap / motion.dt - 1e-9)
        frames = np.arange(0, motion.n_frames - blend - 1, stride)
        if len(frames) < 3:
            raise ValidationError(
                f"kovar: a motion of {motion.n_frames} frames gives {len(frames)} candidate frames; "
                "record longer motion or lower candidate_interval and blend_time"
            )
        configs = [motion.configuration(int(f)) for f in frames]
        far = math.ceil(max(gap, 1) / stride)  # candidates apart at least, for a transition
        # nearer the diagonal than the neighbors of far cells, cells never matter: pruning skips them
        matrix = _Matrix(configs, metric, n_jobs=self.n_jobs, progress=progress, needed=far - 2)
        offers = flockkit.capabilities(metric)
        prune = self.prune and self.per_second is None and bool(offers.pairs_within or offers.lower_bound)
        spread = float(np.mean([np.mean(np.sum((c.positions - c.center_of_mass()) ** 2, axis=1)) for c in configs]))
        threshold, chosen = self._choose(motion, frames, far, matrix, blend, spread, prune)
        transitions = _transitions(frames, chosen, matrix, blend)
        if _kept(motion, frames, chosen, matrix, blend) == 0:
            raise ValidationError(
                self._no_transition_message(motion, frames, far, matrix, blend, threshold, spread, prune)
            )
        params = {
            "candidate_interval": self.candidate_interval,
            "stride": stride,
            "min_gap": self.min_gap,
            "threshold": threshold,
            "threshold_rule": "per_second" if self.per_second else ("absolute" if self.threshold else "adaptive"),
            "per_second": self.per_second,
            "blend_frames": blend,
            "candidates": len(frames),
            "evaluated": matrix.evaluated,
            "prune": self.prune,
            "turn_angle": self.turn_angle,
            "turn_interval": self.turn_interval,
        }
        if self.turn_angle > 0:
            # inside the graph the transitions make, so that turns change no choice made above
            nodes = flockkit.MotionGraph.assemble(motion, transitions).nodes
            every = max(1, round(self.turn_interval / motion.dt))
            transitions += flockkit.graphs.turns(
                motion, np.arange(nodes[0], nodes[-1] - blend + 1, every), angle=self.turn_angle, blend=blend
            )
        graph = flockkit.MotionGraph.assemble(motion, transitions, params=params, provenance={"builder": "kovar"})
        if not self.bridges:
            return graph
        plan = flockkit.graphs.bridge_plan(graph, seconds=self.bridge_seconds, degrees=self.bridge_turn)
        bridged = flockkit.graphs.bridge(
            graph,
            plan,
            behavior=self.bridge_behavior,
            seconds=self.bridge_seconds,
            min_plausibility=self.bridge_plausibility,
            transitions=transitions,
            seed=int(rng.integers(2**32)),
        )
        if self.turn_angle == 0 or "bridge_frames" not in bridged.params:
            return bridged
        # the frames the bridges joined (the recording's dead ends, the solved chain) turn like the rest:
        # without, a walk that enters them goes straight on for as long as they last
        every, origin, low = max(1, round(self.turn_interval / motion.dt)), int(nodes[0]), int(bridged.nodes[0])
        have = {t.start for t in bridged.transitions if t.is_turn}
        first = origin - (origin - low) // every * every  # on the grid of the turns made above
        frames = [f for f in range(first, int(bridged.nodes[-1]) - blend + 1, every) if f not in have]
        kept = [(t.start, t.end, t.alignment, t.blend) for t in bridged.transitions]
        more = flockkit.graphs.turns(bridged.motion, frames, angle=self.turn_angle, blend=blend)
        return flockkit.MotionGraph.assemble(
            bridged.motion, kept + more, params=bridged.params, provenance=bridged.provenance
        )

    def _choose(self, motion, frames, far, matrix, blend, spread, prune):
        """(threshold, chosen minima) by the rule the parameters ask for: the paper's `per_second`,
        an absolute `threshold`, or the adaptive rule (module docstring)."""
        if self.per_second is not None:
            matrix.fill(matrix.all_pairs())
            count = math.ceil(self.per_second * motion.duration)
            chosen = matrix.minima(far)[:count]
            return float(max((matrix.value(*ij) for ij in chosen), default=0.0)), chosen
        if self.threshold is not None:
            if prune:
                matrix.fill_within(self.threshold)
            else:
                matrix.fill(matrix.all_pairs())
            return self.threshold, matrix.minima(far, self.threshold)
        wanted = max(self.min_transitions, math.ceil(self.transitions_per_minute * motion.duration / 60))
        return self._adaptive(motion, frames, far, matrix, blend, spread, wanted, prune)

    def _adaptive(self, motion, frames, far, matrix, blend, spread, wanted, prune):
        """(threshold, chosen minima) by the adaptive rule (module docstring). Without pruning every
        value is computed at once; with it, the minima under a probe threshold are exactly those of
        the full matrix, so probing upwards until the rule is decided gives the identical result."""
        probe, step = self._first_probe(frames, far, matrix, spread, wanted) if prune else (spread, 2)
        count = wanted  # a higher probe only appends minima: the counts tried stay decided
        while True:
            if prune:
                matrix.fill_within(probe)
            else:
                matrix.fill(matrix.all_pairs())
            minima = matrix.minima(far, probe)
            # the lowest minima, adding the shortfall until enough survive the trimming of dead ends
            while count <= len(minima):
                kept = _kept(motion, frames, minima[:count], matrix, blend)
                if kept >= wanted:
                    return float(matrix.value(*minima[count - 1])), minima[:count]
                count += wanted - kept
            if probe >= spread:
                return spread, minima
            probe = min(step * probe, spread)

    def _first_probe(self, frames, far, matrix, spread, wanted) -> tuple[float, float]:
        """A probe threshold likely to decide the adaptive rule at once (module docstring), and the
        factor to raise it by if it does not: small after an estimate, 2 without one."""
        k = len(frames)
        length = int(np.clip(k // 100, 8, 48))
        counts = range(3, k // (2 * length) + 1)  # strips cover at most half the rows
        if not matrix.offers.pairs_within or not counts:
            return _FIRST_PROBE * spread, 2
        far_in_row = np.maximum(k - np.arange(k) - far, 0)  # cells (i, j > i) far enough, per row i
        # as few strips as should hold enough of the minima wanted for a steady estimate
        for count in counts:
            strips, interior, needed = _strips(far_in_row, wanted, length, count)
            if needed >= _STRIP_MINIMA:
                break
        probe = _FIRST_PROBE * spread
        while True:
            matrix.fill_within(probe, ranges=strips)
            values = [matrix.value(i, j) for i, j in matrix.minima(far, probe) if i < j and interior[i]]
            if len(values) >= needed:
                return float(values[needed - 1]), 1.1
            if probe >= spread:
                return spread, 2
            probe = min(2 * probe, spread)

    def _no_transition_message(self, motion, frames, far, matrix, blend, threshold, spread, prune) -> str:
        """Say that no transition is left, with the smallest transition cost and a threshold that
        works: the lowest minima that give a graph, searched upwards from `threshold`, doubling, up
        to the group's mean squared radius (or the threshold, if higher); pruned, computing only
        the pairs each probe needs (the matrix is complete otherwise)."""
        ceiling = max(spread, threshold)
        probe = min(max(threshold, _FIRST_PROBE * spread), ceiling)
        while True:
            if prune:
                matrix.fill_within(probe)
            minima = matrix.minima(far, probe)
            for count in range(1, len(minima) + 1):
                if _kept(motion, frames, minima[:count], matrix, blend):
                    return (
                        f"kovar: threshold {threshold:.4g} leaves no transition; the smallest transition cost is "
                        f"{matrix.value(*minima[0]):.4g}; threshold={float(matrix.value(*minima[count - 1]))!r} "
                        "would give a graph"
                    )
            if probe >= ceiling:
                break
            probe = min(2 * probe, ceiling)
        found = (
            f"the smallest transition cost under it is {matrix.value(*minima[0]):.4g}, and no set of transitions "
            "under it forms a loop"
            if minima
            else "no local minimum of the transition cost at least min_gap apart lies under it"
        )
        return (
            f"kovar: no threshold up to {ceiling:.4g} (the group's mean squared radius, beyond which configurations "
            f"do not resemble each other) gives a walkable graph: {found}; record longer motion, or lower min_gap "
            "or blend_time"
        )


def _strips(far_in_row, wanted, length, count):
    """`count` strips of `length` rows, one in the middle of each of equal parts of the K rows, the
    mask of their interior rows (whose cells have all their neighbors in the strip), and how many
    of the minima wanted their interior should hold (twice its share of the far cells, counted
    per row by `far_in_row`)."""
    k = len(far_in_row)
    strips = [(int(m) - length // 2, int(m) - length // 2 + length) for m in (np.arange(count) + 0.5) * k / count]
    interior = np.zeros(k, dtype=bool)
    for a, b in strips:
        interior[a + 1 : b - 1] = True
    scale = 2 * far_in_row.sum() / max(far_in_row[interior].sum(), 1)  # both directions
    return strips, interior, math.ceil(2 * wanted / scale)


def _transitions(frames, chosen, matrix, blend):
    return [(int(frames[i]), int(frames[j]), matrix.alignment(i, j), blend) for i, j in sorted(chosen)]


def _kept(motion, frames, chosen, matrix, blend) -> int:
    """How many of the chosen transitions survive assembly (dead-end trimming)."""
    if not chosen:
        return 0
    try:
        return len(flockkit.MotionGraph.assemble(motion, _transitions(frames, chosen, matrix, blend)).transitions)
    except ValidationError:
        return 0


class _Matrix:
    """The difference matrix, computed where asked, symmetric; cells not computed count as +inf.
    Only the computed cells are held (sorted by i * K + j, both directions), so that a pruned build
    needs memory for the cells it computes, not K x K. Alignments are only kept for the cells that
    become transitions."""

    def __init__(self, configs, metric, *, n_jobs, progress, needed):
        self.configs, self.metric, self.progress, self.needed = configs, metric, progress, needed
        self.n_jobs = flockkit.parallel.jobs(n_jobs)
        self.offers = flockkit.capabilities(metric)
        self.listed = np.full(len(configs), -np.inf)  # per row, the threshold its pairs were listed at
        # computed cells by key i * K + j, ending with a sentinel key above every cell's
        self._keys, self._values = np.array([np.iinfo(np.int64).max]), np.array([np.inf])
        self._alignments: dict[tuple[int, int], flockkit.Alignment] = {}

    @property
    def evaluated(self) -> int:
        """Cells computed, both directions."""
        return len(self._keys) - 1

    def value(self, i, j):
        """E of cells (i, j) (arrays or ints); +inf where not computed."""
        keys = np.asarray(i, dtype=np.int64) * len(self.configs) + np.asarray(j, dtype=np.int64)
        at = np.searchsorted(self._keys, keys)  # the sentinel keeps it in range
        found = np.where(self._keys[at] == keys, self._values[at], np.inf)
        return found if found.ndim else float(found)

    def minima(self, far: int, probe: float = np.inf) -> list[tuple[int, int]]:
        """Local minima (``flockkit.graphs.local_minima``) of the cells `far` or more candidates apart,
        at most `probe`, lowest first (ties: row-major)."""
        rows, cols = np.divmod(self._keys[:-1], len(self.configs))
        cells = flockkit.graphs.local_minima_of_cells(rows, cols, self._values[:-1], np.abs(rows - cols) >= far)
        values = self.value(cells[:, 0], cells[:, 1])
        order = np.lexsort((cells[:, 1], cells[:, 0], values))
        return [(int(i), int(j)) for i, j in cells[order][values[order] <= probe]]

    def all_pairs(self) -> np.ndarray:
        return np.column_stack(np.triu_indices(len(self.configs), 1))

    def fill_within(self, threshold: float, ranges=None) -> None:
        """Compute every needed pair i < j that the metric cannot rule out at `threshold` (its
        declared pairs_within or lower_bound); with `ranges` (only with pairs_within), only those
        with i in one of the (start, stop) row ranges."""
        pairs = self._listed(threshold, ranges)
        self.fill(pairs[pairs[:, 1] - pairs[:, 0] >= self.needed])

    def _listed(self, threshold, ranges):
        if self.offers.pairs_within:
            # in row ranges, for the workers and for the progress report; rows listed at this
            # threshold or above already are left out
            ranges = ranges or _row_ranges(len(self.configs), 4 * max(abs(self.n_jobs), 2))
            ranges = [run for a, b in ranges for run in _runs(self.listed[a:b] < threshold, a)]
            stage = f"bounding pairs (threshold {threshold:.3g})"
            if self.progress is not None:
                self.progress(0, len(ranges), stage)
            parts = flockkit.parallel.imap(
                _pairs_within, [(self.metric, self.configs, threshold, rows) for rows in ranges], n_jobs=self.n_jobs
            )
            found = [np.zeros((0, 2), dtype=int)]
            for done, part in enumerate(parts, 1):
                found.append(np.asarray(part, dtype=int).reshape(-1, 2))
                if self.progress is not None:
                    self.progress(done, len(ranges), stage)
            for a, b in ranges:
                self.listed[a:b] = threshold
            return np.concatenate(found)
        pairs = self.all_pairs()
        bounds = np.array([self.metric.lower_bound(self.configs[i], self.configs[j]) for i, j in pairs])
        return pairs[bounds <= threshold]

    def fill(self, pairs: np.ndarray) -> None:
        """Compute the distance of every pair (i < j) not computed yet."""
        pairs = pairs[np.isinf(self.value(pairs[:, 0], pairs[:, 1]))]
        if not len(pairs):
            return
        distances = _distances(self.metric, self.configs, pairs, self.n_jobs, self.progress)
        k = len(self.configs)
        keys = np.concatenate([self._keys, pairs[:, 0] * k + pairs[:, 1], pairs[:, 1] * k + pairs[:, 0]])
        order = np.argsort(keys)
        self._keys, self._values = keys[order], np.concatenate([self._values, distances, distances])[order]

    def alignment(self, i: int, j: int) -> flockkit.Alignment:
        """compare(config i, config j): computed for i < j, inverted for i > j."""
        key = (min(i, j), max(i, j))
        if key not in self._alignments:
            self._alignments[key] = self.metric.compare(self.configs[key[0]], self.configs[key[1]])
        return self._alignments[key] if i < j else self._alignments[key].inverse()


def _distances(metric, configs, pairs, n_jobs, progress) -> np.ndarray:
    """metric distances of `pairs`, in chunks (the metric's declared batched `pairwise` where it
    has one), through joblib when n_jobs != 1, reporting `progress(done, total, stage)`."""
    size = int(np.clip(len(pairs) // (8 * max(n_jobs, 1)), 64, 4096)) if n_jobs != 1 else 1024
    chunks = [pairs[s : s + size] for s in range(0, len(pairs), size)]
    # each job gets only the configurations its chunk uses
    calls = [(metric, *(_localized(configs, chunk) if n_jobs != 1 else (configs, chunk))) for chunk in chunks]
    if progress is not None:
        progress(0, len(pairs), "difference matrix")
    results = flockkit.parallel.imap(_chunk_distances, calls, n_jobs=n_jobs)
    found, done = [], 0
    for chunk, distances in zip(chunks, results):
        found.append(distances)
        done += len(chunk)
        if progress is not None:
            progress(done, len(pairs), "difference matrix")
    return np.concatenate(found)


def _row_ranges(k: int, count: int) -> list[tuple[int, int]]:
    """(start, stop) row ranges holding about equal numbers of pairs i < j (row i has k - 1 - i)."""
    done = np.cumsum(np.arange(k - 1, -1, -1))
    cuts = np.searchsorted(done, np.linspace(0, done[-1], count + 1)[1:-1])
    edges = [0, *sorted({int(c) + 1 for c in cuts}), k]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if a < b]


def _runs(mask: np.ndarray, offset: int) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in `mask`, counted from `offset`."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [(offset + int(a), offset + int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _localized(configs, pairs):
    used, local = np.unique(pairs, return_inverse=True)
    return [configs[u] for u in used], local.reshape(pairs.shape)


def _pairs_within(metric, configs, threshold, rows) -> np.ndarray:
    return metric.pairs_within(configs, threshold, rows=rows)


def _chunk_distances(metric, configs, pairs) -> np.ndarray:
    if flockkit.capabilities(metric).pairwise:
        return np.asarray(metric.pairwise(configs, pairs), dtype=np.float64)
    return np.array([metric.compare(configs[i], configs[j]).distance for i, j in pairs])
