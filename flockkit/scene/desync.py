"""De-synchronisation (paper 002, section 6.2): how much of the time neighbouring duplicates play
the same source frames (to within IN_STEP_FRAMES), the share above which one is walked again.

Frames are compared as numbers. For a part whose graph loops (``MotionGraph.period``), the last
frame of the cycle and the first are neighbours too: :func:`in_step` and :func:`part_in_step`
take each part's period and compare around the loop. The scene report keeps the plain
comparison, as ``SceneAnimation.in_step_share`` makes it; the scene decides whom to walk again,
and which parts to warn about, around the loop.

:func:`nearest_in_step` is what the scene report states about the result: over the true nearest
neighbours (each object and the closest object of its template, at any second of the scene,
since objects may move), the share of pairs in step within a tolerance of frames (around the
loop for a looping part) and, for looping parts, of phase (a share of the cycle)."""

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
# The phase tolerance of a looping part in the report: a fortieth of its cycle (one frame of a
# 40-frame cycle; our choice).
IN_STEP_PHASE = 0.025


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


def nearest_pairs(positions: np.ndarray, kinds: np.ndarray, every: int = 1) -> np.ndarray:
    """(P, 2) sorted pairs (i < j): each object and the nearest object of its template, at every
    `every`-th frame of `positions` (objects, frames, 2), all such pairs together."""
    from scipy.spatial import cKDTree

    pairs = set()
    for kind in np.unique(kinds):
        members = np.flatnonzero(kinds == kind)
        if len(members) < 2:
            continue
        for t in range(0, positions.shape[1], every):
            _, nearest = cKDTree(positions[members, t]).query(positions[members, t], k=2)
            for a, b in zip(members, members[nearest[:, 1]]):
                pairs.add((int(min(a, b)), int(max(a, b))))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


def nearest_in_step(animation, *, frames: int = IN_STEP_FRAMES, phase: float = IN_STEP_PHASE) -> dict:
    """How out of step the true nearest neighbours of `animation` (a SceneAnimation) play: over
    :func:`nearest_pairs` (at every second), the share of pairs that play in step on more than
    MAX_IN_STEP of frames, a pair in step on a frame where some part of each plays source frames
    at most `frames` apart (around the loop for a looping part): ``nearest_pairs_in_step``; and
    the same with looping parts compared by phase, at most `phase` of their cycle apart (parts
    that do not loop by frames): ``nearest_pairs_in_phase``. Also the pairs counted and the
    tolerances."""
    positions, _ = animation.transforms()
    every = max(1, round(1.0 / animation.dt))
    pairs = nearest_pairs(positions, np.asarray(animation.placement.templates), every)
    played = animation.source_frames()
    periods = [[g.period for g in _graphs(t)] for t in animation.templates]

    def share(**within) -> float:
        if not len(pairs):
            return 0.0
        return float(np.mean([_close(played[i], played[[j]], periods[animation.placement.templates[i]], **within)
                              .any(axis=1).mean() > MAX_IN_STEP for i, j in pairs]))  # fmt: skip

    return {"nearest_pairs": len(pairs), "nearest_pairs_in_step": share(within=frames),
            "nearest_pairs_in_phase": share(within=frames, phase=phase), "in_step_tolerance_frames": frames,
            "in_step_tolerance_phase": phase}  # fmt: skip


def _graphs(template) -> tuple:
    from .templates import template_view

    return template_view(template).graphs


def _close(frames, others, periods, within: int = IN_STEP_FRAMES, phase: float | None = None) -> np.ndarray:
    """(K, parts, F): whether frames and others play within `within` frames of each other (a
    looping part around its loop; with `phase`, within that share of its cycle instead)."""
    apart = np.abs(frames[None] - others)
    close = apart <= within
    if periods is not None:
        cycle = np.zeros(frames.shape[0], dtype=np.int64)  # parts an object lacks play -1: never close
        given = [p or 0 for p in periods][: len(cycle)]
        cycle[: len(given)] = given
        looping = (cycle > 0)[None, :, None]
        if looping.any():
            around = np.where(looping, cycle[None, :, None], 1)
            apart = np.minimum(apart % around, around - apart % around)
            close = np.where(looping, apart / around <= phase if phase is not None else apart <= within, close)
    return close & (frames[None] >= 0) & (others >= 0)
