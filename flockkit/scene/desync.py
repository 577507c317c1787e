"""De-synchronisation (paper 002, section 6.2): how much of the time neighbouring duplicates play
the same source frames, the share above which one is walked again."""

from __future__ import annotations

import numpy as np

# Neighbouring duplicates may play the same source frame at the same time on at most this share
# of frames (the bar); beyond it, section 6.2 walks one of them again.
MAX_IN_STEP = 0.05


# Same-template objects whose positions are closer than this many footprint diagonals are
# neighbours (they are seen together).
NEIGHBOUR_DIAGONALS = 3.0


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


def in_step(frames: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Share of frames on which `frames` (parts, F) and each of `others` (K, parts, F) play the
    same source frame in some part: (K,)."""
    same = (frames[None] == others) & (frames[None] >= 0)
    return same.any(axis=1).mean(axis=1)
