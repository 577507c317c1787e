"""De-synchronisation (paper 002, section 6.2): how much of the time neighbouring duplicates play
the same source frames (to within IN_STEP_FRAMES), the share above which one is walked again.

Frames are compared as numbers. For a part whose graph loops (``MotionGraph.period``), the last
frame of the cycle and the first are neighbours too: :func:`in_step` and :func:`part_in_step`
take each part's period and compare around the loop. The scene report keeps the plain
comparison, as ``SceneAnimation.in_step_share`` makes it; the scene decides whom to walk again,
and which parts to warn about, around the loop."""

from __future__ import annotations

import numpy as np

# Neighbouring duplicates may play the same source frame at the same time on at most this share
# of frames (the bar); beyond it, section 6.2 walks one of them again.
MAX_IN_STEP = 0.05


# Same-template objects whose positions are closer than this many footprint diagonals are
# neighbours (they are seen together), and so are each object's NEAREST closest ones, however far:
# two lone objects seen side by side must not play alike.
NEIGHBOUR_DIAGONALS = 3.0
NEAREST = 2

# Two objects play in step on a frame when a part of each plays source frames at most this many
# frames apart: one frame apart is as alike to the eye as the same frame (and is what the walks'
# `avoid` term steers away from).
IN_STEP_FRAMES = 1


def stacked(played, n_frames: int) -> np.ndarray:
    """(objects, parts, frames) of each object's (parts, frames) source frames, -1 where an
    object has fewer parts than the most."""
    frames = np.full((len(played), max(len(own) for own in played), n_frames), -1, dtype=np.int64)
    for i, own in enumerate(played):
        frames[i, : len(own)] = own
    return frames


def largest_in_step(frames: np.ndarray, neighbours) -> float:
    """The largest in-step share (see in_step) between an object and one of its neighbours."""
    shares = [in_step(frames[i], frames[near]).max() for i, near in enumerate(neighbours) if len(near)]
    return float(max(shares, default=0.0))


def pairs_in_step(frames: np.ndarray, neighbours) -> float:
    """The share of neighbour pairs in step (see in_step) on more than MAX_IN_STEP of frames."""
    pairs = {(min(i, j), max(i, j)) for i, near in enumerate(neighbours) for j in near}
    if not pairs:
        return 0.0
    first, second = (np.array(side) for side in zip(*sorted(pairs)))
    return float(np.mean([in_step(frames[i], frames[[j]])[0] > MAX_IN_STEP for i, j in zip(first, second)]))


def in_step(frames: np.ndarray, others: np.ndarray, periods=None) -> np.ndarray:
    """Share of frames on which `frames` (parts, F) and each of `others` (K, parts, F) play source
    frames at most IN_STEP_FRAMES apart in some part: (K,). `periods` (one per part, None or 0
    where a part does not loop) compares around each looping part's cycle."""
    return _close(frames, others, periods).any(axis=1).mean(axis=1)


def part_in_step(frames: np.ndarray, others: np.ndarray, periods=None) -> np.ndarray:
    """As :func:`in_step`, each part on its own: (K, parts)."""
    return _close(frames, others, periods).mean(axis=2)


def _close(frames, others, periods) -> np.ndarray:
    """(K, parts, F): whether frames and others play within IN_STEP_FRAMES of each other."""
    apart = np.abs(frames[None] - others)
    if periods is not None:
        cycle = np.zeros(frames.shape[0], dtype=np.int64)  # parts an object lacks play -1: never close
        given = [p or 0 for p in periods][: len(cycle)]
        cycle[: len(given)] = given
        looping = cycle > 0
        if looping.any():
            around = np.where(looping, cycle, 1)[None, :, None]
            apart = np.where(looping[None, :, None], np.minimum(apart % around, around - apart % around), apart)
    return (apart <= IN_STEP_FRAMES) & (frames[None] >= 0) & (others >= 0)
