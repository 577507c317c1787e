"""Conformance checks for controllers (``flockkit.interfaces.Controller``).

Each check is ``check_<property>(name, controller)``. Controllers are built from whatever clips
their author chose, so the checks ask only what the contract promises, at times that run over
several seconds (through a clip's loops and a graph walk's transitions).
"""

from __future__ import annotations

import numpy as np

from ..skeleton import Event, Pose, Skeleton
from ._expect import applies_when, expect_validation_error

TIMES = np.linspace(0.0, 7.3, 74)  # seconds on the stream's clock: past several loops of a short clip
TIMES.setflags(write=False)  # each check hands a component a copy: one that sorts in place harms no other check


def check_poses_fit_the_skeleton(name, controller):
    """pose(times) is a Pose of shape (len(times),) for the controller's skeleton, with unit
    rotations and finite translations."""
    skeleton = getattr(controller, "skeleton", None)
    assert isinstance(skeleton, Skeleton), f"{name}.skeleton is {type(skeleton).__name__}, not a flockkit.Skeleton"
    pose = controller.pose(TIMES.copy())
    assert isinstance(pose, Pose), f"{name}.pose returned {type(pose).__name__}, not a flockkit.Pose"
    assert pose.shape == (len(TIMES),), f"{name}.pose gave poses of shape {pose.shape} for {len(TIMES)} times"
    assert pose.n_joints == skeleton.n_joints, (
        f"{name}.pose gave {pose.n_joints} joints; its skeleton has {skeleton.n_joints}"
    )
    lengths = np.linalg.norm(pose.rotations, axis=-1)
    assert np.allclose(lengths, 1.0, atol=1e-6), (
        f"{name}.pose gave rotations of length {lengths.min()}..{lengths.max()}"
    )
    assert np.all(np.isfinite(pose.translations)), f"{name}.pose gave translations that are not finite"


def check_pose_is_a_function_of_time(name, controller):
    """The pose at a time is the same asked in one batch, one at a time, or in reverse order."""
    batch = controller.pose(TIMES.copy())
    backwards = controller.pose(TIMES[::-1].copy())
    for k in (0, 17, 45, len(TIMES) - 1):
        alone = controller.pose(TIMES[k : k + 1].copy())
        for other, what in ((alone, "alone"), (backwards[len(TIMES) - 1 - k : len(TIMES) - k], "in reverse order")):
            same = np.allclose(batch.rotations[k], other.rotations[0], atol=1e-9) and np.allclose(
                batch.translations[k], other.translations[0], atol=1e-9
            )
            assert same, f"{name}.pose at t = {TIMES[k]:.3g} s differs asked {what} and in a batch"


def check_events_split_by_windows(name, controller):
    """events(start, stop) gives Events in [start, stop), in time order; consecutive windows give
    together what their union gives."""
    whole = controller.events(0.0, float(TIMES[-1]))
    assert all(isinstance(e, Event) for e in whole), f"{name}.events returned something that is not an Event"
    times = [e.time for e in whole]
    assert times == sorted(times), f"{name}.events are not in time order"
    assert all(0.0 <= t < TIMES[-1] for t in times), f"{name}.events gave times outside the window"
    cuts = np.concatenate([[0.0], np.sort(np.random.default_rng(0).uniform(0, TIMES[-1], 9)), [TIMES[-1]]])
    pieces = [e for a, b in zip(cuts[:-1], cuts[1:]) for e in controller.events(float(a), float(b))]
    assert [(e.time, e.name) for e in pieces] == [(e.time, e.name) for e in whole], (
        f"{name}.events over consecutive windows differ from events over their union (lost or repeated)"
    )


def check_rejects_bad_times(name, controller):
    """Negative, non-finite or non-1D times raise flockkit.errors.ValidationError."""
    expect_validation_error(lambda: controller.pose(np.array([0.0, -1.0])), f"{name}.pose(a negative time)")
    expect_validation_error(lambda: controller.pose(np.array([np.nan])), f"{name}.pose(NaN)")
    expect_validation_error(lambda: controller.pose(np.zeros((2, 2))), f"{name}.pose(a 2D array)")


def check_times_unchanged(name, controller):
    """pose leaves the array of times it is given as it was."""
    shuffled = np.random.default_rng(1).permutation(TIMES)
    times = shuffled.copy()
    controller.pose(times)
    assert np.array_equal(times, shuffled), f"{name}.pose changed the times it was given"


@applies_when("root_motion")
def check_root_motion_on_the_ground(name, controller):
    """root_motion(times) is a finite float array (len(times), 4): zero at time 0, and 0 along
    the skeleton's up axis (a translation on the ground and a heading)."""
    found = np.asarray(controller.root_motion(TIMES.copy()))
    assert found.shape == (len(TIMES), 4), f"{name}.root_motion gave shape {found.shape} for {len(TIMES)} times"
    assert np.all(np.isfinite(found)), f"{name}.root_motion gave values that are not finite"
    assert np.allclose(found[0], 0.0, atol=1e-9), f"{name}.root_motion at time 0 is {found[0]}, not zero"
    up = "xyz".index(controller.skeleton.up_axis)
    assert np.allclose(found[:, up], 0.0, atol=1e-9), (
        f"{name}.root_motion moves along the skeleton's up axis {controller.skeleton.up_axis!r} (root motion is on "
        "the ground)"
    )


@applies_when("root_motion")
def check_root_motion_is_a_function_of_time(name, controller):
    """root_motion at a time is the same asked in one batch, alone, or in reverse order."""
    batch = np.asarray(controller.root_motion(TIMES.copy()))
    backwards = np.asarray(controller.root_motion(TIMES[::-1].copy()))[::-1]
    assert np.allclose(batch, backwards, atol=1e-9), f"{name}.root_motion differs asked in reverse order"
    for k in (0, 17, 45, len(TIMES) - 1):
        alone = np.asarray(controller.root_motion(TIMES[k : k + 1].copy()))
        assert np.allclose(batch[k], alone[0], atol=1e-9), (
            f"{name}.root_motion at t = {TIMES[k]:.3g} s differs asked alone and in a batch"
        )


@applies_when("root_motion")
def check_root_motion_is_continuous(name, controller):
    """root_motion does not jump where the poses do not (a loop adds its motion rather than going
    back to its start): over steps of a hundredth of a second, no step of the translation or the
    heading is more than 20 times the median step plus a millionth of the skeleton's size."""
    times = np.arange(0.0, float(TIMES[-1]), 0.01)
    found = np.asarray(controller.root_motion(times))
    size = float(np.ptp(controller.skeleton.positions(controller.skeleton.rest), axis=0).max()) or 1.0
    for what, steps, scale in (
        ("translation", np.linalg.norm(np.diff(found[:, :3], axis=0), axis=1), size),
        ("heading", np.abs(np.diff(found[:, 3])), 1.0),
    ):
        limit = 20 * np.median(steps) + 1e-6 * scale
        worst = int(np.argmax(steps))
        assert steps[worst] <= limit, (
            f"{name}.root_motion's {what} jumps by {steps[worst]:.4g} between t = {times[worst]:.2f} s and "
            f"{times[worst + 1]:.2f} s (its median step is {np.median(steps):.3g})"
        )


CHECKS = (
    check_poses_fit_the_skeleton,
    check_pose_is_a_function_of_time,
    check_events_split_by_windows,
    check_rejects_bad_times,
    check_times_unchanged,
    check_root_motion_on_the_ground,
    check_root_motion_is_a_function_of_time,
    check_root_motion_is_continuous,
)
