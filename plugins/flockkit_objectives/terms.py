"""Objective terms of paper 004, section 3.4.2, in log space, one value per frame.

Each term reads its constants from the Problem (sigma_com, shape_weight c_S, flock_weight c_F,
flocks F_c, visibility), so one Problem describes the whole objective.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError


def _window(motion, problem, start, stop) -> tuple[int, int]:
    if not isinstance(motion, flockkit.Motion):
        raise ValidationError(f"objective: motion must be a flockkit.Motion; got {type(motion).__name__}")
    if not isinstance(problem, flockkit.Problem):
        raise ValidationError(f"objective: problem must be a flockkit.Problem; got {type(problem).__name__}")
    if motion.n_agents != problem.n_agents or motion.dims != problem.dims:
        raise ValidationError(
            f"objective: the motion has {motion.n_agents} agents in {motion.dims}D, the problem {problem.n_agents} in "
            f"{problem.dims}D"
        )
    return validate.window(motion, start, stop, owner="objective")


def _active(problem, kind, start, stop):
    """(frame, constraint) for constraints of `kind` whose frame lies in [start, stop)."""
    for constraint in problem.constraints:
        frame = problem.frame(constraint.time)
        if isinstance(constraint, kind) and start <= frame < stop:
            yield frame, constraint


class ComTerm:
    """log g_c: at a COM-constrained frame, log N(COM error; 0, sigma_com) per constraint."""

    def log_terms(self, motion, problem, start=0, stop=None) -> np.ndarray:
        start, stop = _window(motion, problem, start, stop)
        terms = np.zeros(stop - start)
        sigma = problem.sigma_com
        for frame, constraint in _active(problem, flockkit.ComConstraint, start, stop):
            agents = list(problem.agents_of(constraint))
            error = motion.positions[frame, agents].mean(axis=0) - constraint.position
            terms[frame - start] += -math.log(sigma * math.sqrt(2 * math.pi)) - float(error @ error) / (2 * sigma**2)
        return terms


class ShapeTerm:
    """log g_s: at a shape-constrained frame, -c_S times the summed squared distance of the
    constrained agents outside the shape (zero inside)."""

    def log_terms(self, motion, problem, start=0, stop=None) -> np.ndarray:
        start, stop = _window(motion, problem, start, stop)
        terms = np.zeros(stop - start)
        for frame, constraint in _active(problem, flockkit.ShapeConstraint, start, stop):
            outside = np.maximum(
                constraint.shape.signed_distance(motion.positions[frame, list(problem.agents_of(constraint))]), 0.0
            )
            terms[frame - start] -= problem.shape_weight * float(outside @ outside)
        return terms


class FlockTerm:
    """log g_f: -c_F |F - F_c| at every frame, F the number of connected groups when agents closer
    than ``problem.visibility`` see each other."""

    def log_terms(self, motion, problem, start=0, stop=None) -> np.ndarray:
        start, stop = _window(motion, problem, start, stop)
        counts = count_flocks(motion.positions[start:stop], problem.visibility)
        return -problem.flock_weight * np.abs(np.atleast_1d(counts) - problem.flocks).astype(float)


# Agents per frame up to which frames are compared all pairs at once (N x N per frame), in blocks
# of frames of about this many pairs (tables that stay in cache: 3-4x faster than larger blocks).
_DENSE_UP_TO = 256
_PAIRS_PER_BLOCK = 20_000


def count_flocks(positions: np.ndarray, visibility: float):
    """Connected components of the graph joining agents closer than `visibility`: an int for one
    configuration (N, D), an array (F,) for F frames (F, N, D), found in one pass over all frames
    (each frame's agents a separate block of one graph)."""
    frames = np.asarray(positions)
    single = frames.ndim == 2
    frames = frames[None] if single else frames
    f, n = frames.shape[:2]
    if not f or not n:
        return 0 if single else np.zeros(f, dtype=int)
    block = max(1, _PAIRS_PER_BLOCK // (n * n))
    if n <= _DENSE_UP_TO and f > block:
        counts = np.concatenate([count_flocks(frames[k : k + block], visibility) for k in range(0, f, block)])
    elif n <= _DENSE_UP_TO:  # per frame an N x N table of who sees whom, axis by axis (no (F, N, N, D) temporary)
        axes = np.ascontiguousarray(np.moveaxis(frames, 2, 0))
        squared = np.zeros((f, n, n))
        for coordinate in axes:
            offset = coordinate[:, None, :] - coordinate[:, :, None]
            offset *= offset
            squared += offset
        close = squared < visibility * visibility
        # A sampled flock is mostly one group: a breadth-first search from agent 0, every frame at
        # once (products with the table), settles the frames it reaches whole; only the others
        # are labelled, by scipy.
        table = close.astype(np.float32)
        reached = close[:, 0, :] | (np.arange(n) == 0)
        while True:
            grown = (table @ reached[:, :, None].astype(np.float32))[:, :, 0] > 0
            grown |= reached
            if np.array_equal(grown, reached):
                break
            reached = grown
        counts = np.ones(f, dtype=int)
        split = np.flatnonzero(~reached.all(axis=1))
        if len(split):
            counts[split] = _components(close[split])
    else:
        pairs = [cKDTree(x).query_pairs(visibility, output_type="ndarray") + k * n for k, x in enumerate(frames)]
        i, j = np.concatenate(pairs).T if pairs else (np.zeros(0, int), np.zeros(0, int))
        counts = _counts(coo_matrix((np.ones(len(i)), (i, j)), shape=(f * n, f * n)), f, n)
    return int(counts[0]) if single else counts


def _components(close: np.ndarray) -> np.ndarray:
    """Groups per frame of (F, N, N) tables of who sees whom, each frame a block of one graph."""
    f, n = close.shape[:2]
    flat = close.reshape(f * n, n)
    rows, j = np.nonzero(flat)
    indptr = np.zeros(f * n + 1, dtype=np.int64)
    np.cumsum(np.count_nonzero(flat, axis=1), out=indptr[1:])
    return _counts(csr_matrix((np.ones(len(j), dtype=np.int8), j + rows // n * n, indptr), shape=(f * n, f * n)), f, n)


def _counts(graph, f: int, n: int) -> np.ndarray:
    labels = np.sort(connected_components(graph, directed=False)[1].reshape(f, n), axis=1)
    return 1 + np.count_nonzero(np.diff(labels, axis=1), axis=1)
