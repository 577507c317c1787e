"""Conformance checks for segmenters (``flockkit.interfaces.Segmenter``).

Each check is ``check_<property>(name, segmenter)``; they segment the kit's ``inputs.parts``: a
motion of three groups of points, one still and two rigid ones that swing at different times;
rigid bodies that turn as they travel; and motions whose points all move alike
(``inputs.degenerate_configurations`` gliding or swaying), so every segmenter has an answer that is
clearly right.

A segmenter declaring ``Capabilities(skin=True)`` is given a skin with each input
(``inputs.chain_skin``: each group of points on a chain of joints of its own, which the segmenter
must merge where the group moves as one), and is also checked on ``inputs.limbs``, a skinned body
with two limbs whose parts are known, and for refusing a missing or ill-fitting skin.
"""

from __future__ import annotations

import numpy as np

from ..interfaces import capabilities
from ..motion import Motion
from ..scene.segmentation import Segmentation, same_partition
from ._expect import applies_when, dims_of, expect_validation_error, fixed_by, on_input
from .inputs import chain_skin, limbs, parts


def _skin(segmenter, motion, groups=None):
    """The kit's skin of `motion` (its points in `groups`, None: one group) for a segmenter that
    declares ``Capabilities.skin``; None for others."""
    if not capabilities(segmenter).skin:
        return None
    return chain_skin(motion.positions[0], np.zeros(motion.n_agents, dtype=np.int64) if groups is None else groups)


def _segment(segmenter, motion, seed=0, groups=None, skin=None):
    """`segmenter`'s segmentation of `motion`, given `skin` (else the kit's skin of `groups`)
    where it declares ``Capabilities.skin``."""
    rng = np.random.default_rng(seed)
    if not capabilities(segmenter).skin:
        return segmenter.segment(motion, rng)
    return segmenter.segment(motion, rng, skin=_skin(segmenter, motion, groups) if skin is None else skin)


def check_labels_cover_every_point(name, segmenter):
    """segment returns a Segmentation with one label per point, every part non-empty."""
    for dims in dims_of(segmenter):
        motion, truth = parts(dims=dims)
        with on_input(name, segmenter, dims, "the kit's parts"):
            result = _segment(segmenter, motion, groups=truth)
        assert isinstance(result, Segmentation), f"{name}.segment returned {type(result).__name__}, not a Segmentation"
        assert result.n_points == motion.n_agents, (
            f"{name}.segment labels {result.n_points} points; the motion has {motion.n_agents}"
        )


def _kit_parts(name, segmenter):
    """(labels, truth) of every declared dimension's ``inputs.parts``."""
    for dims in dims_of(segmenter):
        motion, truth = parts(dims=dims)
        with on_input(name, segmenter, dims, "the kit's parts"):
            yield _segment(segmenter, motion, groups=truth).labels, truth


@fixed_by("label by how points move (energies, velocities), never by where they are or by their index")
def check_still_points_apart_from_moving_ones(name, segmenter):
    """Points that never move (the kit's still group) share no part with points that move."""
    for labels, truth in _kit_parts(name, segmenter):
        still = truth == 0
        assert not np.isin(labels[still], labels[~still]).any(), f"{name}.segment puts still points with moving ones"


@fixed_by(
    "do not merge parts whose motions differ in time: two groups that swing at different times are "
    "independent, whatever their sizes or the amount they move"
)
def check_independent_groups_apart(name, segmenter):
    """Two rigid groups that move at different times (the kit's flap and tail) share no part."""
    for labels, truth in _kit_parts(name, segmenter):
        assert not np.isin(labels[truth == 1], labels[truth == 2]).any(), (
            f"{name}.segment puts two groups that move at different times in one part"
        )


def _rigid_bodies(dims: int) -> dict[str, Motion]:
    """A rigid cloud of 30 points turning as it travels, swinging as it glides, spinning in place."""
    body = np.random.default_rng(31).uniform(-1.0, 1.0, (30, dims))
    t = np.arange(61) * 0.1
    ahead = np.eye(dims)[0]
    found = {}
    for label, angle, travel in (("turning as it travels", 0.8 * t, 1.5 * t),
                                 ("swinging as it glides", 0.6 * np.sin(2 * np.pi * 0.7 * t), t),
                                 ("spinning in place", 1.5 * t, 0 * t)):  # fmt: skip
        turns = np.zeros((len(t), dims, dims))
        turns[:, :2, :2] = np.stack([np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)], -1).reshape(-1, 2, 2)
        if dims == 3:
            turns[:, 2, 2] = 1.0
        positions = np.einsum("tij,nj->tni", turns, body) + travel[:, None, None] * ahead + 5.0
        found[f"a rigid body {label}"] = Motion(positions=positions, dt=0.1)
    return found


@fixed_by(
    "a rigid body's points move differently (those far from its turning centre more), yet nothing in "
    "it moves independently: merge parts that together move rigidly (each frame a rotation and "
    "translation of the first), or segment motion relative to the best rigid fit"
)
def check_rigid_body_is_one_part(name, segmenter):
    """Every point of each kit group that swings rigidly shares one part, and so does a rigid body
    that turns as it travels, swings as it glides or spins in place."""
    for labels, truth in _kit_parts(name, segmenter):
        for group in (1, 2):
            assert len(np.unique(labels[truth == group])) == 1, (
                f"{name}.segment splits a rigid group of the kit's parts into {len(np.unique(labels[truth == group]))}"
            )
    for dims in dims_of(segmenter):
        for label, motion in _rigid_bodies(dims).items():
            with on_input(name, segmenter, dims, label):
                result = _segment(segmenter, motion)
                assert result.n_parts == 1, f"{name}.segment splits {label} into {result.n_parts} parts; expected one"


def check_deterministic(name, segmenter):
    """The same seed gives the same labels, part names included (three runs of each of three
    seeds, so that randomness not drawn from `rng` cannot agree by chance)."""
    motion, truth = parts(dims=dims_of(segmenter)[0])
    for seed in (3, 4, 5):
        first = _segment(segmenter, motion, seed, truth)
        for _ in range(2):
            again = _segment(segmenter, motion, seed, truth)
            assert np.array_equal(first.labels, again.labels), (
                f"{name}.segment gives other labels for the same seed ({seed}): draw every random choice from rng"
            )


def _waving_sheet(dims: int) -> Motion:
    """A strip of 40 points carrying a travelling wave whose amplitude grows along it: motion
    that varies smoothly from point to point, so where parts begin is the segmenter's choice and
    any dependence on the points' order shows (clean rigid parts hide it: every method agrees)."""
    x = np.linspace(0.0, 4.0, 40)
    t = np.arange(80)[:, None] * 0.05
    positions = np.zeros((80, len(x), dims))
    positions[..., 0] = x
    positions[..., 1] = 0.3 * np.sin(3.0 * t - 1.7 * x) * x / 4.0
    return Motion(positions=positions, dt=0.05)


@fixed_by(
    "random starts that pick points by index (k-means++ seeds, ICA's initial matrix over points) "
    "find other parts when the points come in another order: take the points in a canonical order "
    "(sorted by their trajectories) before any seeded choice, and map the labels back"
)
def check_order_of_points_does_not_matter(name, segmenter):
    """Shuffling the points shuffles the labels with them: the same partition, up to part names,
    on the kit's rigid parts and on a waving sheet where part boundaries are a free choice."""
    dims = dims_of(segmenter)[0]
    for label, motion in (("the kit's parts", parts(dims=dims)[0]), ("a waving sheet", _waving_sheet(dims))):
        skin = _skin(segmenter, motion, parts(dims=dims)[1] if label == "the kit's parts" else None)
        labels = _segment(segmenter, motion, skin=skin).labels
        for seed in (5, 6):
            order = np.random.default_rng(seed).permutation(motion.n_agents)
            shuffled = Motion(positions=motion.positions[:, order], dt=motion.dt)
            again = _segment(segmenter, shuffled, skin=None if skin is None else skin.take(order)).labels
            assert same_partition(labels[order], again), (
                f"{name}.segment depends on the order of the points (on {label} in {dims}D)"
            )


def check_inputs_unchanged(name, segmenter):
    """segment leaves the motion (and a skin) as it was."""
    motion, truth = parts(dims=dims_of(segmenter)[0])
    before = motion.positions.copy()
    skin = _skin(segmenter, motion, truth)
    weights = None if skin is None else skin.weights.copy()
    _segment(segmenter, motion, skin=skin)
    assert np.array_equal(before, motion.positions), f"{name}.segment changed its motion"
    assert skin is None or np.array_equal(weights, skin.weights), f"{name}.segment changed its skin"


def check_rejects_bad_motion(name, segmenter):
    """Something that is not a Motion raises flockkit.errors.ValidationError."""
    motion, truth = parts(dims=dims_of(segmenter)[0])
    extra = {"skin": _skin(segmenter, motion, truth)} if capabilities(segmenter).skin else {}
    expect_validation_error(lambda: segmenter.segment(motion.positions, np.random.default_rng(0), **extra),
                            f"{name}.segment(an array, not a Motion)")  # fmt: skip


def _degenerate_motions(dims: int) -> dict[str, Motion]:
    """Motions where every moving point moves alike: one part is the answer for each."""
    from .inputs import degenerate_configurations

    shapes = {label.split(",")[0]: config.positions for label, config in degenerate_configurations(dims)}
    t = np.arange(61)[:, None, None] * 0.1
    ahead = np.eye(dims)[0]
    found = {}
    for label in ("a square", "a grid", "five agents on one spot", "seven agents on a line", "one agent"):
        positions = shapes[label]
        found[f"{label} gliding at constant speed"] = Motion(positions=positions + t * ahead, dt=0.1)
        found[f"{label} swaying together"] = Motion(positions=positions + np.sin(2 * t) * ahead, dt=0.1)
    found["a grid at rest"] = Motion(positions=np.broadcast_to(shapes["a grid"], (61, *shapes["a grid"].shape)), dt=0.1)
    return found


@fixed_by(
    "points whose motion is the same (a rigid group gliding at constant speed, points on one spot) "
    "carry the same information: group identical series before decomposing or clustering, and "
    "return one part when nothing tells points apart; never split by position or index"
)
def check_identical_motion_is_one_part(name, segmenter):
    """Points that all move alike (a square, a grid, points on one spot or on a line, gliding at
    constant speed or swaying together; a grid at rest; a lone point) are one part."""
    for dims in dims_of(segmenter):
        for label, motion in _degenerate_motions(dims).items():
            with on_input(name, segmenter, dims, label):
                result = _segment(segmenter, motion)
                assert result.n_points == motion.n_agents and result.n_parts == 1, (
                    f"{name}.segment splits {label} into {result.n_parts} parts; its points move alike: expected one"
                )


@applies_when("skin")
def check_rejects_missing_or_unfitting_skin(name, segmenter):
    """A segmenter that needs a skin raises flockkit.errors.ValidationError without one (skin=None)
    and for a skin of another number of points."""
    motion, truth = parts(dims=dims_of(segmenter)[0])
    rng = np.random.default_rng(0)
    expect_validation_error(lambda: segmenter.segment(motion, rng, skin=None), f"{name}.segment(skin=None)")
    fewer = chain_skin(motion.positions[0, :-1], truth[:-1])
    expect_validation_error(lambda: segmenter.segment(motion, rng, skin=fewer),
                            f"{name}.segment(a skin of {fewer.n_vertices} points for {motion.n_agents})")  # fmt: skip


@applies_when("skin")
@fixed_by(
    "start from the skin's joints and join joints whose vertices move together (rigidly, over the whole "
    "motion); keep apart joints that move independently of each other"
)
def check_skinned_limbs_found(name, segmenter):
    """On ``inputs.limbs`` (a body and two limbs, each rigid on joints of its own, swinging
    independently), the parts are exactly the body and each limb."""
    for dims in dims_of(segmenter):
        mesh, truth = limbs(dims=dims)
        with on_input(name, segmenter, dims, "the kit's skinned limbs"):
            labels = _segment(segmenter, mesh.motion, skin=mesh.skin).labels
        found = [sorted(set(truth[labels == k].tolist())) for k in np.unique(labels)]
        assert same_partition(labels, truth), (
            f"{name}.segment finds {len(found)} parts holding the kit's groups {found}; expected the body, the left "
            "limb and the right limb apart (3 parts)"
        )


CHECKS = (
    check_labels_cover_every_point,
    check_still_points_apart_from_moving_ones,
    check_independent_groups_apart,
    check_rigid_body_is_one_part,
    check_identical_motion_is_one_part,
    check_deterministic,
    check_order_of_points_does_not_matter,
    check_inputs_unchanged,
    check_rejects_bad_motion,
    check_rejects_missing_or_unfitting_skin,
    check_skinned_limbs_found,
)
