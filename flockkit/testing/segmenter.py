"""Conformance checks for segmenters (``flockkit.interfaces.Segmenter``).

Each check is ``check_<property>(name, segmenter)``; they segment the kit's ``inputs.parts``: a
motion of three groups of points, one still and two that move at different times, and motions
whose points all move alike (``inputs.degenerate_configurations`` gliding or swaying), so every
segmenter has an answer that is clearly right.
"""

from __future__ import annotations

import numpy as np

from ..motion import Motion
from ..scene.segmentation import Segmentation, same_partition
from ._expect import dims_of, expect_validation_error, fixed_by, on_input
from .inputs import parts


def _segment(segmenter, motion, seed=0):
    return segmenter.segment(motion, np.random.default_rng(seed))


def check_labels_cover_every_point(name, segmenter):
    """segment returns a Segmentation with one label per point, every part non-empty."""
    for dims in dims_of(segmenter):
        motion, _ = parts(dims=dims)
        with on_input(name, segmenter, dims, "the kit's parts"):
            result = _segment(segmenter, motion)
        assert isinstance(result, Segmentation), f"{name}.segment returned {type(result).__name__}, not a Segmentation"
        assert result.n_points == motion.n_agents, (
            f"{name}.segment labels {result.n_points} points; the motion has {motion.n_agents}"
        )


def check_still_points_apart_from_moving_ones(name, segmenter):
    """Points that never move share no part with points that move, and points that move together
    (a rigid group) share one."""
    for dims in dims_of(segmenter):
        motion, truth = parts(dims=dims)
        labels = _segment(segmenter, motion).labels
        still = truth == 0
        assert not np.isin(labels[still], labels[~still]).any(), f"{name}.segment puts still points with moving ones"
        for group in np.unique(truth[~still]):
            assert len(np.unique(labels[truth == group])) == 1, f"{name}.segment splits a group that moves as one"


def check_deterministic(name, segmenter):
    """The same seed gives the same labels."""
    motion, _ = parts(dims=dims_of(segmenter)[0])
    for seed in (3, 4):
        first, second = _segment(segmenter, motion, seed), _segment(segmenter, motion, seed)
        assert np.array_equal(first.labels, second.labels), f"{name}.segment differs for the same seed"


def check_order_of_points_does_not_matter(name, segmenter):
    """Shuffling the points shuffles the labels with them: the same partition, up to part names."""
    motion, _ = parts(dims=dims_of(segmenter)[0])
    order = np.random.default_rng(5).permutation(motion.n_agents)
    shuffled = Motion(positions=motion.positions[:, order], dt=motion.dt)
    labels = _segment(segmenter, motion).labels
    again = _segment(segmenter, shuffled).labels
    assert same_partition(labels[order], again), f"{name}.segment depends on the order of the points"


def check_inputs_unchanged(name, segmenter):
    """segment leaves the motion as it was."""
    motion, _ = parts(dims=dims_of(segmenter)[0])
    before = motion.positions.copy()
    _segment(segmenter, motion)
    assert np.array_equal(before, motion.positions), f"{name}.segment changed its motion"


def check_rejects_bad_motion(name, segmenter):
    """Something that is not a Motion raises flockkit.errors.ValidationError."""
    motion, _ = parts(dims=dims_of(segmenter)[0])
    expect_validation_error(lambda: segmenter.segment(motion.positions, np.random.default_rng(0)),
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


CHECKS = (
    check_labels_cover_every_point,
    check_still_points_apart_from_moving_ones,
    check_identical_motion_is_one_part,
    check_deterministic,
    check_order_of_points_does_not_matter,
    check_inputs_unchanged,
    check_rejects_bad_motion,
)
