"""The scene report's de-synchronisation figures over the true nearest neighbours: pairs in step
within a tolerance of frames (around the loop for a looping part) and of phase."""

import numpy as np
import pytest

from flockkit.scene import desync

from .test_short_cycles import PERIOD, flock_of_birds


def test_tolerances_of_frames_and_of_phase_around_the_loop():
    frames = np.array([[0], [0]])  # two parts, one frame
    others = np.array([[[39], [39]], [[2], [2]], [[41], [1]]])
    periods = [40, None]  # part 0 loops over 40 frames, part 1 does not
    close = desync._close(frames, others, periods)[:, :, 0]
    assert close.tolist() == [[True, False], [False, False], [True, True]]  # 0 and 39: one frame around the loop
    by_phase = desync._close(frames, others, periods, phase=0.05)[:, :, 0]  # two frames of 40
    assert by_phase.tolist() == [[True, False], [True, False], [True, True]]
    assert desync._close(frames, others, periods, within=2)[:, 1, 0].tolist() == [False, True, True]


def test_nearest_pairs_are_each_objects_closest_of_its_template():
    rng = np.random.default_rng(4)
    positions = rng.uniform(0, 10, (30, 3, 2))  # 30 objects, 3 frames
    kinds = rng.integers(0, 2, 30)
    found = {tuple(p) for p in desync.nearest_pairs(positions, kinds).tolist()}
    expected = set()
    for t in range(3):
        for i in range(30):
            same = [j for j in range(30) if j != i and kinds[j] == kinds[i]]
            j = min(same, key=lambda j: np.linalg.norm(positions[i, t] - positions[j, t]))
            expected.add((min(i, j), max(i, j)))
    assert found == expected
    assert desync.nearest_pairs(positions, kinds, every=5).shape[0] < len(expected)  # frame 0 only


def test_the_report_gives_the_nearest_pairs_in_step_and_the_short_cycle_bar_holds():
    animation, _ = flock_of_birds()
    report = animation.report
    frames = animation.source_frames()
    places = animation.placement.positions
    distance = np.linalg.norm(places[:, None] - places[None], axis=2) + np.diag(np.full(len(places), np.inf))
    pairs = {(min(i, int(j)), max(i, int(j))) for i, j in enumerate(distance.argmin(axis=1))}

    def in_step(i, j, near):  # on more than 5% of frames some part plays within `near` of the other's
        return np.mean([any(near(a, b) for a, b in zip(frames[i, :, t], frames[j, :, t]))
                        for t in range(frames.shape[2])]) > 0.05  # fmt: skip

    def around(a, b):
        return min(abs(a - b) % PERIOD, PERIOD - abs(a - b) % PERIOD)

    within_frame = np.mean([in_step(i, j, lambda a, b: around(a, b) <= 1) for i, j in pairs])
    within_phase = np.mean([in_step(i, j, lambda a, b: around(a, b) / PERIOD <= 0.025) for i, j in pairs])
    assert report["nearest_pairs"] == len(pairs) and report["in_step_tolerance_frames"] == 1
    assert report["nearest_pairs_in_step"] == pytest.approx(within_frame)
    assert report["nearest_pairs_in_phase"] == pytest.approx(within_phase)
    assert report["nearest_pairs_in_step"] <= 0.05  # the bar: at most 5% of neighbour pairs within one frame
    looser = desync.nearest_in_step(animation, frames=PERIOD // 2, phase=0.5)
    assert looser["nearest_pairs_in_step"] == looser["nearest_pairs_in_phase"] == 1.0  # any two frames are close
