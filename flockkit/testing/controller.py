"""Conformance checks for controllers (``flockkit.interfaces.Controller``).

Each check is ``check_<property>(name, controller)``. Controllers are built from whatever clips
their author chose, so the checks ask only what the contract promises, at times that run over
several seconds (through a clip's loops and a graph walk's transitions).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ..skeleton import Event, Pose, Skeleton
from ._expect import applies_unless, applies_when, expect_validation_error

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


@applies_unless("live")
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
@applies_unless("live")
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


FRAME = 1 / 30  # seconds between a live controller's frames in the checks


@applies_when("batch")
def check_batch_equals_pose(name, controller):
    """batch([controller, a copy]).write(...) writes each controller's pose at each time (asked in
    any order, the same controller twice in one call) as pose gives it, to float32, and touches
    nothing else in the array."""
    j = controller.skeleton.n_joints
    other = copy.deepcopy(controller)
    evaluator = controller.batch([controller, other])
    index = np.array([0, 1, 0, 1, 0, 1])
    times = np.array([0.0, 0.5, 3.1, 7.3, 1.7, 0.0])
    stride = 13  # not the store's 12: a batch must write at the stride it is given
    out = np.full(len(index) * j * stride + 5, -7.0, dtype=np.float32)
    rows = (np.arange(len(index))[::-1] * j * stride + 5).astype(np.int64)
    evaluator.write(index, times, out, rows, stride)
    assert np.all(out[:5] == -7.0), f"{name}.batch wrote outside the rows it was given"
    for i, (k, t) in enumerate(zip(index, times)):
        block = out[rows[i] : rows[i] + j * stride].reshape(j, stride)
        expected = (controller, other)[k].pose(np.array([t]))
        assert np.allclose(block[:, 0:4], expected.rotations[0], atol=1e-6) and np.allclose(
            block[:, 4:7], expected.translations[0], atol=1e-5
        ), f"{name}.batch wrote a pose at t = {t} s that differs from {name}.pose at that time"
        assert np.all(block[:, 7:] == -7.0), f"{name}.batch wrote past a joint's rotation and translation"


def _probe_values(controller) -> dict:
    """Two values of each input of a live controller, apart: its range's ends, or 1 from a finite end."""
    found = {}
    for field, (low, high) in dict(controller.inputs).items():
        a = low if math.isfinite(low) else (min(high, 0.0) - 1.0 if math.isfinite(high) else -1.0)
        b = high if math.isfinite(high) else a + 1.0
        found[field] = (float(a), float(b))
    return found


def _run(controller, frames: int, feeds: dict | None = None) -> Pose:
    """Ask `controller` for frames 0 .. frames - 1 one a frame; `feeds` (frame -> inputs) fed
    before that frame's pose. Returns the last frame's pose."""
    pose = None
    for frame in range(frames):
        if feeds and frame in feeds:
            controller.feed(**feeds[frame])
        pose = controller.pose(np.array([frame * FRAME]))
    return pose


@applies_when("live")
def check_live_input_shows_in_the_next_pose(name, controller):
    """Inputs fed before a frame change that frame's pose: two copies run alike for 6 frames, then
    fed an input's two ends, differ at the 7th (for at least one input)."""
    assert dict(getattr(controller, "inputs", {})), f"{name}.inputs names no input"
    changed = []
    for field, (low, high) in _probe_values(controller).items():
        a, b = copy.deepcopy(controller), copy.deepcopy(controller)
        first = _run(a, 7, {6: {field: low}})
        second = _run(b, 7, {6: {field: high}})
        changed.append(not (np.allclose(first.rotations, second.rotations, atol=1e-9)
                            and np.allclose(first.translations, second.translations, atol=1e-9)))  # fmt: skip
    assert any(changed), f"{name}: no input fed before a frame changed that frame's pose"


@applies_when("live")
def check_live_same_inputs_same_poses(name, controller):
    """Two copies fed the same inputs at the same frames give the same poses."""
    feeds = {frame: {field: values[frame % 2] for field, values in _probe_values(controller).items()}
             for frame in (0, 3, 5, 8)}  # fmt: skip
    a, b = copy.deepcopy(controller), copy.deepcopy(controller)
    for frames in (4, 9):
        first, second = _run(a, frames, feeds), _run(b, frames, feeds)
        assert np.array_equal(first.rotations, second.rotations) and np.array_equal(
            first.translations, second.translations
        ), f"{name} gave different poses for the same inputs at the same times"


@applies_when("live")
def check_live_rejects_bad_inputs(name, controller):
    """feed with an unknown input name, or a value that is not a finite number in range, raises
    flockkit.errors.ValidationError."""
    fed = copy.deepcopy(controller)
    expect_validation_error(lambda: fed.feed(no_such_input=1.0), f"{name}.feed(an unknown input)")
    field = next(iter(dict(controller.inputs)))
    expect_validation_error(lambda: fed.feed(**{field: float("nan")}), f"{name}.feed({field}=NaN)")
    low, _ = dict(controller.inputs)[field]
    if math.isfinite(low):
        expect_validation_error(lambda: fed.feed(**{field: low - 1.0}), f"{name}.feed({field} below its range)")


CHECKS = (
    check_poses_fit_the_skeleton,
    check_pose_is_a_function_of_time,
    check_events_split_by_windows,
    check_rejects_bad_times,
    check_times_unchanged,
    check_root_motion_on_the_ground,
    check_root_motion_is_a_function_of_time,
    check_root_motion_is_continuous,
    check_batch_equals_pose,
    check_live_input_shows_in_the_next_pose,
    check_live_same_inputs_same_poses,
    check_live_rejects_bad_inputs,
)
