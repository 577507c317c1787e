"""Conformance checks for configuration metrics (``flockkit.interfaces.ConfigurationMetric``).

Each check is ``check_<property>(name, metric)`` and raises AssertionError saying what is wrong.
They compare configurations of random flocks (one agent to fifteen, in the dimensions the metric
declares), so results are reproducible; rigid copies are made with rotations in general position.
Tied and symmetric configurations (``inputs.degenerate_configurations``) are compared too.
The checks of ``lower_bound``, ``pairs_within`` and ``pairwise`` run only where declared.
"""

from __future__ import annotations

import numpy as np

from ..motion import Alignment, Configuration, State, random_flock
from ._expect import agents, applies_when, dims_of, expect_validation_error, fixed_by, on_input

SEED = 4205
_SIZES = {2: (1, 6, 15), 3: (5, 12)}  # agents per configuration, per dimension


def _rotation(dims: int, rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((dims, dims)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def _configurations(metric) -> list[Configuration]:
    return [
        random_flock(n_agents=n, dims=d, rng=np.random.default_rng(SEED + 100 * d + n)).configuration()
        for d in dims_of(metric)
        for n in _SIZES[d]
    ]


def _rigid_copy(config: Configuration, rng) -> Configuration:
    rotation = _rotation(config.dims, rng)
    order = rng.permutation(config.n_agents)
    shift = rng.normal(0, 10, config.dims)
    return Configuration(
        positions=(config.positions @ rotation.T + shift)[order], velocities=(config.velocities @ rotation.T)[order]
    )


def _pairs(metric):
    rng = np.random.default_rng(SEED + 1)
    for config in _configurations(metric):
        other = random_flock(n_agents=config.n_agents, dims=config.dims, rng=rng).configuration()
        yield config, other


def _each(name, metric, items):
    """(item, context) where the context names the configurations' size in failures."""
    for item in items:
        first = item[0] if isinstance(item, tuple) else item
        yield item, on_input(name, metric, first.dims, f"configurations of {agents(first.n_agents)}")


def _scale(config: Configuration) -> float:
    return max(1.0, float(np.sum(config.positions**2) / config.n_agents))


def check_compare_returns_alignment(name, metric):
    """compare returns a flockkit.Alignment sized for the configurations."""
    for (a, b), context in _each(name, metric, _pairs(metric)):
        with context:
            found = metric.compare(a, b)
            assert isinstance(found, Alignment), (
                f"{name}.compare returned {type(found).__name__}, not a flockkit.Alignment"
            )
            assert found.assignment.shape == (a.n_agents,) and found.rotation.shape == (a.dims, a.dims), (
                f"{name}.compare returned an alignment for {agents(found.assignment.shape[0])} in "
                f"{found.rotation.shape[0]}D; expected {a.n_agents} in {a.dims}D"
            )


def check_identical_is_zero(name, metric):
    """A configuration is at distance zero from itself."""
    for config, context in _each(name, metric, _configurations(metric)):
        with context:
            distance = metric.compare(config, config).distance
            assert distance <= 1e-9 * _scale(config), f"{name}.compare(a, a).distance = {distance}; expected 0"


def check_rigid_and_permutation_invariant(name, metric):
    """A rotated, translated and reordered copy is at distance zero, and the alignment maps it back."""
    rng = np.random.default_rng(SEED + 2)
    for config, context in _each(name, metric, _configurations(metric)):
        with context:
            copy = _rigid_copy(config, rng)
            found = metric.compare(config, copy)
            tolerance = 1e-8 * _scale(config)
            assert found.distance <= tolerance, (
                f"{name}: a rigid, reordered copy is at distance {found.distance}; expected 0"
            )
            residual = found.residual(config, copy)
            assert residual <= tolerance, (
                f"{name}: the alignment leaves the copy {residual} away (mean squared); expected 0"
            )


def check_distance_covers_alignment(name, metric):
    """The distance is at least the mean squared position residual of the alignment it returns."""
    for a, b in _pairs(metric):
        found = metric.compare(a, b)
        residual = found.residual(a, b)
        assert found.distance >= residual - 1e-9 * _scale(a), (
            f"{name}.compare reports distance {found.distance} but its alignment leaves a mean squared residual of "
            f"{residual}"
        )


def _noisy_copies(metric):
    """(a, b, known) with b a rigid, reordered copy of a whose positions carry small noise (0.02),
    velocities turned with it, and `known` the mean squared position residual of the alignment the
    kit made b with (the true rotation and correspondence, centres matched), under which the
    velocities match exactly."""
    rng = np.random.default_rng(SEED + 8)
    for a in _configurations(metric):
        noisy = a.positions + rng.normal(0.0, 0.02, a.positions.shape)
        rotation, order, shift = _rotation(a.dims, rng), rng.permutation(a.n_agents), rng.normal(0, 10, a.dims)
        b = Configuration(positions=(noisy @ rotation.T + shift)[order], velocities=(a.velocities @ rotation.T)[order])
        x, y = a.positions - a.positions.mean(axis=0), noisy - noisy.mean(axis=0)
        yield a, b, float(np.mean(np.sum((x - y) ** 2, axis=1)))


@fixed_by(
    "return the mean over agents of squared distances (not their sum, not its square root), minimised "
    "over rotations, translations and assignments; a velocity term, if any, must vanish when the "
    "velocities match under the alignment"
)
def check_distance_is_a_mean_of_squares(name, metric):
    """The distance is at most the mean squared residual of an alignment the kit knows (a noisy
    rigid, reordered copy with matching velocities): a minimum over alignments of a mean of squared
    distances, not a sum over agents or a root mean square."""
    for (a, b, known), context in _each(name, metric, _noisy_copies(metric)):
        with context:
            found = metric.compare(a, b).distance
            guess = ("a sum over agents" if np.isclose(found, a.n_agents * known, rtol=0.05)
                     else "a root" if np.isclose(found, np.sqrt(known), rtol=0.05) else "not a minimum")  # fmt: skip
            assert found <= known * (1 + 1e-6) + 1e-9 * _scale(a), (
                f"{name}.compare(a, b).distance = {found:.6g} exceeds {known:.6g}, the mean squared residual of a "
                f"known alignment of b (a's agents moved by noise of 0.02, then rigidly moved and reordered; {guess}?)"
            )


@fixed_by(
    "compute the distance from a and b in a way that does not depend on their order: search the same "
    "rotations and assignments both ways (an alignment of b onto a, inverted, aligns a onto b)"
)
def check_symmetric(name, metric):
    """compare(a, b) and compare(b, a) give the same distance: a distance between group
    configurations does not depend on which is named first."""
    for (a, b), context in _each(name, metric, _pairs(metric)):
        with context:
            forth, back = metric.compare(a, b).distance, metric.compare(b, a).distance
            assert np.isclose(forth, back, rtol=1e-6, atol=1e-9 * _scale(a)), (
                f"{name}.compare(a, b).distance = {forth:.6g} but compare(b, a).distance = {back:.6g}"
            )


def _chains(metric):
    """Triples (a, b, c) of configurations, b a small step from a and c a step further on, with
    b and c rigidly moved and reordered (so distances come from the search, not the labels)."""
    rng = np.random.default_rng(SEED + 6)
    for a in _configurations(metric):
        step = rng.normal(0, 0.3, a.positions.shape), rng.normal(0, 0.3, a.velocities.shape)
        b = Configuration(positions=a.positions + step[0], velocities=a.velocities + step[1])
        c = Configuration(positions=b.positions + step[0], velocities=b.velocities + step[1])
        yield a, _rigid_copy(b, rng), _rigid_copy(c, rng)


@fixed_by(
    "return a mean squared distance after the best alignment (its root is then a true distance, so "
    "d(a, c) <= 2 (d(a, b) + d(b, c))); a distance that grows faster than squared residuals (squared "
    "again, exponentiated) breaks the graph builders' pruning and thresholds"
)
def check_relaxed_triangle(name, metric):
    """The distance behaves as a squared distance: d(a, c) <= 2 (d(a, b) + d(b, c)), which holds
    whenever the square root of the distance is a distance (as for a mean squared residual
    minimised over rigid motions and assignments). Builders rely on it to rule out blocks of
    neighbouring frames together."""
    for (a, b, c), context in _each(name, metric, _chains(metric)):
        with context:
            ab, bc, ac = (metric.compare(x, y).distance for x, y in ((a, b), (b, c), (a, c)))
            assert ac <= 2 * (ab + bc) + 1e-9 * _scale(a), (
                f"{name}: d(a, c) = {ac:.6g} exceeds 2 (d(a, b) + d(b, c)) = {2 * (ab + bc):.6g} for configurations "
                "b a step from a and c a step further on"
            )


@fixed_by(
    "do not break ties by agent index or trust principal axes: where distances to the centre or "
    "principal spreads are equal (a square, a grid), try every agent the tie allows as the anchor "
    "of the alignment, and handle every agent on one spot, a lone agent and agents on one line"
)
def check_degenerate_configurations(name, metric):
    """Tied and symmetric configurations (a square, a hexagon, a grid, agents on one spot, pairs
    of coincident agents, a lone agent, agents on a line; at rest, heading one way, turning) are
    at distance zero from their rigid, reordered copies, both ways, and the alignment maps each
    copy back."""
    from .inputs import degenerate_configurations

    rng = np.random.default_rng(SEED + 7)
    for d in dims_of(metric):
        for label, config in degenerate_configurations(d):
            with on_input(name, metric, d, label):
                copy = _rigid_copy(config, rng)
                tolerance = 1e-8 * _scale(config)
                for found, first, second in ((metric.compare(config, copy), config, copy),
                                             (metric.compare(copy, config), copy, config)):  # fmt: skip
                    assert found.distance <= tolerance, (
                        f"{name}: a rigid, reordered copy of {label} is at distance {found.distance:.6g}; expected 0"
                    )
                    residual = found.residual(first, second)
                    assert residual <= tolerance, (
                        f"{name}: the alignment of {label} with its copy leaves {residual:.6g} (mean squared); "
                        "expected 0"
                    )


@applies_when("lower_bound")
def check_lower_bound(name, metric):
    """lower_bound(a, b) never exceeds compare(a, b).distance, on random pairs and on rigid
    copies of random and of tied, symmetric configurations."""
    from .inputs import degenerate_configurations

    rng = np.random.default_rng(SEED + 3)
    tied = [c for d in dims_of(metric) for _, c in degenerate_configurations(d)]
    for a, b in [*_pairs(metric), *((c, _rigid_copy(c, rng)) for c in [*_configurations(metric), *tied])]:
        raw = metric.lower_bound(a, b)
        assert isinstance(raw, (float, np.floating)), f"{name}.lower_bound returned {type(raw).__name__}, not a float"
        bound, distance = float(raw), metric.compare(a, b).distance
        assert np.isfinite(bound) and bound <= distance + 1e-9 * _scale(a), (
            f"{name}.lower_bound = {bound} exceeds compare's distance {distance}"
        )


def _close_configurations(metric) -> list[Configuration]:
    """Configurations of the kit's recording a few frames apart: some pairs are close, some not."""
    from .inputs import recording

    motion = recording(n_agents=6, seconds=6.0, dims=dims_of(metric)[0], seed=SEED)
    return [motion.configuration(t) for t in range(0, 60, 4)]


@applies_when("pairs_within")
def check_pairs_within(name, metric):
    """pairs_within(configurations, threshold) lists every pair i < j whose compare distance is at
    most the threshold, each once; with rows=(start, stop), those with start <= i < stop."""
    configs = _close_configurations(metric)
    pairs = np.column_stack(np.triu_indices(len(configs), 1))
    distances = np.array([metric.compare(configs[i], configs[j]).distance for i, j in pairs])
    for threshold in np.quantile(distances, [0.1, 0.5]):
        listed = np.asarray(metric.pairs_within(configs, float(threshold)))
        assert listed.ndim == 2 and listed.shape[1] == 2, (
            f"{name}.pairs_within returned shape {listed.shape}; expected (P, 2)"
        )
        listed_set = {(int(i), int(j)) for i, j in listed}
        assert len(listed_set) == len(listed) and all(i < j for i, j in listed_set), (
            f"{name}.pairs_within must list pairs (i, j) with i < j, each once"
        )
        missing = [
            (int(i), int(j)) for (i, j), d in zip(pairs, distances) if d <= threshold and (i, j) not in listed_set
        ]
        assert not missing, (
            f"{name}.pairs_within(threshold={threshold:.4g}) leaves out {missing[:3]} although compare finds them "
            "within it"
        )
        split = len(configs) // 3
        ranges = ((0, split), (split, len(configs)))
        parts = [
            np.asarray(metric.pairs_within(configs, float(threshold), rows=rows)).reshape(-1, 2) for rows in ranges
        ]
        assert {(int(i), int(j)) for part in parts for i, j in part} == listed_set and all(
            start <= i < stop for part, (start, stop) in zip(parts, ranges) for i, _ in part
        ), f"{name}.pairs_within(rows=...) over two row ranges does not give the same pairs as without rows"


@applies_when("pairwise")
def check_pairwise(name, metric):
    """pairwise(configurations, pairs) gives compare's distances: for the listed pairs, and
    without `pairs` for every i < j in row-major (pdist) order."""
    rng = np.random.default_rng(SEED + 4)
    configs = [random_flock(n_agents=6, dims=dims_of(metric)[0], rng=rng).configuration() for _ in range(4)]
    pairs = np.array([[2, 0], [1, 3], [0, 1]])
    for given, expected_pairs in ((pairs, pairs), (None, np.column_stack(np.triu_indices(4, 1)))):
        found = metric.pairwise(configs) if given is None else metric.pairwise(configs, given)
        assert isinstance(found, np.ndarray) and found.dtype == np.float64, (
            f"{name}.pairwise returned {type(found).__name__} of {getattr(found, 'dtype', 'no dtype')}, "
            "not a float64 numpy array"
        )
        assert found.shape == (len(expected_pairs),), (
            f"{name}.pairwise returned shape {found.shape}; expected ({len(expected_pairs)},)"
        )
        for (i, j), value in zip(expected_pairs, found):
            expected = metric.compare(configs[i], configs[j]).distance
            assert np.isclose(value, expected, rtol=1e-9, atol=1e-12), (
                f"{name}.pairwise gives {value} for pair ({i}, {j}) but compare gives {expected}"
            )


def check_deterministic(name, metric):
    """The same pair gives the same alignment twice."""
    for a, b in _pairs(metric):
        assert metric.compare(a, b) == metric.compare(a, b), (
            f"{name}.compare gives different alignments for the same pair"
        )


def check_inputs_unchanged(name, metric):
    """compare leaves both configurations as they were."""
    for a, b in _pairs(metric):
        before = [x.copy() for x in (a.positions, a.velocities, b.positions, b.velocities)]
        metric.compare(a, b)
        after = (a.positions, a.velocities, b.positions, b.velocities)
        assert all(np.array_equal(x, y) for x, y in zip(before, after)), f"{name}.compare changed its input"


def check_rejects_mismatched_sizes(name, metric):
    """Configurations of different sizes or dimensions, and anything that is not a
    flockkit.Configuration (a State, an array of positions), raise flockkit.errors.ValidationError."""
    rng = np.random.default_rng(SEED + 5)
    d = dims_of(metric)[0]
    base = random_flock(n_agents=5, dims=d, rng=rng).configuration()
    others = (random_flock(n_agents=6, dims=d, rng=rng), random_flock(n_agents=5, dims=5 - d, rng=rng))
    for other in (o.configuration() for o in others):
        expect_validation_error(
            lambda other=other: metric.compare(base, other),
            f"{name}.compare of {agents(base.n_agents)} in {d}D with {other.n_agents} in {other.dims}D",
        )
    state = State(positions=base.positions, velocities=base.velocities)
    for other, what in ((state, "a State"), (np.array(base.positions), "an array of positions")):
        expect_validation_error(lambda other=other: metric.compare(base, other), f"{name}.compare(a, {what})")


CHECKS = (
    check_compare_returns_alignment,
    check_identical_is_zero,
    check_rigid_and_permutation_invariant,
    check_distance_covers_alignment,
    check_distance_is_a_mean_of_squares,
    check_symmetric,
    check_relaxed_triangle,
    check_degenerate_configurations,
    check_lower_bound,
    check_pairs_within,
    check_pairwise,
    check_deterministic,
    check_inputs_unchanged,
    check_rejects_mismatched_sizes,
)
