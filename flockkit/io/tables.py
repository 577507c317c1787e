"""Captured motion in tables: wide and long text tables (CSV, TSV, whitespace) and (T, N, D)
.npy arrays read into a Motion, and motions written back as CSV and JSON.

Captures do not record their frame rate in a form these readers can trust, so every reader takes
``dt=`` (seconds per frame) or ``fps=``.

Missing values (NaN, or empty fields in a table, or frames or agents absent from a long table)
follow one policy, :func:`fill_gaps`: a run of at most `max_gap` missing frames of an agent is
filled, linearly between its neighbors, or with the nearest known position at the start or end
of the recording; a longer run raises ValidationError naming the file, the agents and the frames.
``max_gap=0`` accepts no missing value at all.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import numpy as np

from .. import _files, _npzfile, validate
from .._atomic import atomic_path
from ..errors import FileFormatError, ValidationError
from ..motion import Motion
from ..validate import allocation, integer

__all__ = ["read_wide", "read_long", "read_npy", "fill_gaps", "write_csv", "write_json", "DEFAULT_MAX_GAP"]

# Longest run of missing frames filled by interpolation: 10 frames is 0.4 s at the 25 fps of the
# pedestrian captures, 0.67 s at the sticklebacks' 15 fps; longer gaps are more than a blink of
# the tracker and are reported instead (our choice).
DEFAULT_MAX_GAP = 10


def _dt(dt, fps) -> float:
    if (dt is None) == (fps is None):
        raise ValidationError(
            "give the frame rate as exactly one of dt= (seconds per frame) or fps= (frames per second)"
        )
    value, name = (dt, "dt") if dt is not None else (fps, "fps")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ValidationError(f"{name} must be a number > 0; got {value!r}")
    return float(dt) if dt is not None else 1.0 / float(fps)


def _runs(missing: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in a 1-D boolean array."""
    edges = np.diff(np.concatenate([[0], missing.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def fill_gaps(
    positions, *, max_gap: int = DEFAULT_MAX_GAP, source: str = "positions", agent_names=None, frame_numbers=None
) -> np.ndarray:
    """Fill missing (NaN) positions of a (T, N, D) array by the module's policy; returns a copy.

    An agent is missing at a frame if any of its coordinates is NaN. Raises ValidationError,
    naming `source`, the agents and the frames, for runs longer than `max_gap` frames or an agent
    that is never seen. `agent_names` and `frame_numbers` are how the message names them
    (default: their indices).
    """
    max_gap = integer(max_gap, "max_gap", minimum=0)
    filled = np.array(positions, dtype=np.float64)
    if filled.ndim != 3:
        raise ValidationError(f"{source}: positions must have shape (T, N, D); got {filled.shape}")
    missing = np.isnan(filled).any(axis=2)
    if np.isinf(filled).any():
        raise ValidationError(f"{source}: positions hold infinite values")
    too_long = []
    frames = np.arange(filled.shape[0])
    names = list(range(filled.shape[1])) if agent_names is None else [_plain(n) for n in agent_names]
    numbers = frames if frame_numbers is None else [_plain(n) for n in frame_numbers]
    for agent in np.flatnonzero(missing.any(axis=0)):
        gaps = _runs(missing[:, agent])
        known = ~missing[:, agent]
        if not known.any():
            too_long.append(f"agent {names[agent]}: never seen")
            continue
        too_long += [f"agent {names[agent]}: frames {numbers[a]}..{numbers[b - 1]}" for a, b in gaps if b - a > max_gap]
        for axis in range(filled.shape[2]):
            column = filled[:, agent, axis]
            # np.interp holds the end values outside the known frames: the nearest position.
            column[~known] = np.interp(frames[~known], frames[known], column[known])
    if too_long:
        shown = "; ".join(too_long[:8]) + (f"; and {len(too_long) - 8} more" if len(too_long) > 8 else "")
        raise ValidationError(
            f"{source}: missing positions longer than max_gap={max_gap} frames ({shown}); raise max_gap, or select "
            "agents and frames where every agent is seen"
        )
    return filled


def _plain(value):
    return int(value) if float(value).is_integer() else float(value)


def _motion(
    positions,
    dt,
    max_gap,
    source,
    *,
    frames=None,
    agents=None,
    agent_names=None,
    frame_numbers=None,
    image_height=None,
) -> Motion:
    positions = np.asarray(positions, dtype=np.float64)
    if image_height is not None:
        # image rows count down from the top; flockkit's y points up (pictures, exports)
        height = validate.number(image_height, f"{source}: image_height (pixels)", minimum=0, strict=True)
        positions = positions.copy()
        positions[..., 1] = height - positions[..., 1]
    agent_names = np.arange(positions.shape[1]) if agent_names is None else np.asarray(agent_names)
    frame_numbers = np.arange(positions.shape[0]) if frame_numbers is None else np.asarray(frame_numbers)
    if agents is not None:
        positions, agent_names = positions[:, list(agents)], agent_names[list(agents)]
    if frames is not None:
        positions, frame_numbers = positions[frames], frame_numbers[frames]
    positions = fill_gaps(
        positions, max_gap=max_gap, source=source, agent_names=agent_names, frame_numbers=frame_numbers
    )
    try:
        return Motion(positions=positions, dt=dt)
    except ValidationError as exc:
        raise ValidationError(f"{source}: {exc}") from None


def _table(path: Path, delimiter) -> tuple[np.ndarray, int]:
    """The numeric rows of a delimited text file (header lines skipped) and the first data line."""
    text = _files.read_bytes(path).decode("utf-8-sig", errors="replace").splitlines()  # -sig: drop a BOM
    lines = [
        (number, line) for number, line in enumerate(text, 1) if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise FileFormatError(f"{path}: no data rows")
    if delimiter is None:
        sample = lines[0][1]
        delimiter = "\t" if "\t" in sample else "," if "," in sample else None
    rows, first = [], None
    for number, line in lines:
        fields = next(csv.reader([line], delimiter=delimiter)) if delimiter else line.split()
        try:
            rows.append([float(f) if f.strip() else math.nan for f in fields])
        except ValueError:
            if number == lines[0][0]:
                continue  # a header line
            raise FileFormatError(f"{path}, line {number}: not all fields are numbers: {line[:80]!r}") from None
        first = first or number
        if len(rows[-1]) != len(rows[0]):
            raise FileFormatError(
                f"{path}, line {number}: {len(rows[-1])} fields where line {first} has {len(rows[0])}"
            )
    if not rows:
        raise FileFormatError(f"{path}: no numeric rows")
    return np.array(rows), first


def _frame_index(path, frames: np.ndarray, agents: int, dims: int, max_gap) -> tuple[np.ndarray, np.ndarray]:
    """Row -> frame slot, and the frame number of every slot, for frame numbers on a regular grid
    (gaps in it become missing frames). Gaps longer than `max_gap` frames (None: no limit) and
    grids larger than memory are refused before the grid is made."""
    if not np.all(np.isfinite(frames)) or not np.all(frames == np.round(frames)) or np.any(np.abs(frames) > 2**53):
        raise FileFormatError(f"{path}: the frame column must hold whole numbers (of magnitude at most 2**53)")
    unique = np.unique(frames.astype(np.int64))
    step = int(np.gcd.reduce(np.diff(unique))) if len(unique) > 1 else 1
    missing = np.diff(unique) // step - 1  # whole frames missing between consecutive frame numbers
    if max_gap is not None and np.any(missing > max_gap):
        at = int(np.argmax(missing > max_gap))
        raise ValidationError(
            f"{path}: frames {unique[at] + step}..{unique[at + 1] - step} are missing for every agent "
            f"({int(missing[at])} frames, more than max_gap={max_gap}); raise max_gap or read the parts apart"
        )
    slots = (unique[-1] - unique[0]) // step + 1
    allocation(float(slots) * agents * dims, f"{path}: a grid of {slots} frames x {agents} agents")
    return (frames.astype(np.int64) - unique[0]) // step, np.arange(unique[0], unique[-1] + 1, step)


def _unique_rows(path, keys: np.ndarray, what: str) -> None:
    """Refuse a table that gives the same `keys` (rows of numbers) twice, naming the first."""
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        row = keys[first[np.argmax(counts > 1)]]
        raise FileFormatError(f"{path}: {what} {', '.join(f'{v:g}' for v in row)} is given more than once")


def read_wide(
    path,
    *,
    dt=None,
    fps=None,
    dims: int = 2,
    delimiter=None,
    max_gap: int = DEFAULT_MAX_GAP,
    agents=None,
    image_height=None,
) -> Motion:
    """Read a wide table: one row per frame, ``frame, x1, y1, [z1,] x2, y2, ...``.

    A header line is skipped. `agents` selects agents (0-based) before the missing-value policy.
    Frame numbers may step by any constant; frames absent from the grid count as missing.
    `image_height` (pixels): the positions are image coordinates, y pointing down, as video
    trackers write them; y becomes ``image_height - y`` so that it points up, as flockkit's
    pictures and exports expect.
    """
    path = Path(path)
    dt = _dt(dt, fps)
    dims = validate.dims(dims)
    table, _ = _table(path, delimiter)
    columns = table.shape[1] - 1
    if columns < dims or columns % dims:
        raise FileFormatError(
            f"{path}: {columns} coordinate columns after the frame column is not a multiple of dims={dims}"
        )
    _unique_rows(path, table[:, :1], "frame")
    count = columns // dims
    if agents is not None:
        agents = list(agents) if not isinstance(agents, (str, bytes)) else [agents]
        if any(isinstance(a, bool) or not isinstance(a, (int, np.integer)) or not 0 <= a < count for a in agents):
            raise ValidationError(f"{path}: agents must be indices in 0..{count - 1}; got {agents!r}")
        if len(set(agents)) != len(agents):
            raise ValidationError(f"{path}: agents must be distinct; got {agents!r}")
    slots, numbers = _frame_index(path, table[:, 0], count, dims, max_gap)
    positions = np.full((len(numbers), count, dims), np.nan)
    positions[slots] = table[:, 1:].reshape(len(table), -1, dims)
    return _motion(positions, dt, max_gap, str(path), agents=agents, frame_numbers=numbers, image_height=image_height)


def read_long(
    path,
    *,
    dt=None,
    fps=None,
    dims: int = 2,
    delimiter=None,
    max_gap: int = DEFAULT_MAX_GAP,
    agents=None,
    frames=None,
    image_height=None,
) -> Motion:
    """Read a long table: one row per agent and frame, ``frame, agent, x, y[, z]``.

    Agents are ordered by id; `agents` selects ids (as in the file), `frames` a slice of frame
    slots, both before the missing-value policy (so a window where a crowd's members are all
    present can be read from a scene where people come and go). `image_height` as in read_wide.
    """
    path = Path(path)
    dt = _dt(dt, fps)
    dims = validate.dims(dims)
    table, _ = _table(path, delimiter)
    if table.shape[1] != 2 + dims:
        raise FileFormatError(
            f"{path}: a long table in {dims}D has {2 + dims} columns (frame, agent, coordinates); found "
            f"{table.shape[1]}"
        )
    _unique_rows(path, table[:, :2], "frame and agent")
    ids = np.unique(table[:, 1])
    # a frame selection may skip a long gap, so the gap rule waits for the selected frames
    slots, numbers = _frame_index(path, table[:, 0], len(ids), dims, max_gap if frames is None else None)
    if agents is not None:
        wanted = np.asarray(agents, dtype=np.float64)
        unknown = sorted(set(wanted.tolist()) - set(ids.tolist()))
        if unknown:
            raise ValidationError(f"{path}: no agents with ids {unknown[:8]}")
        ids = wanted
    column = {agent: i for i, agent in enumerate(ids.tolist())}
    keep = np.array([agent in column for agent in table[:, 1].tolist()])
    positions = np.full((len(numbers), len(ids), dims), np.nan)
    positions[slots[keep], [column[a] for a in table[keep, 1].tolist()]] = table[keep, 2:]
    return _motion(
        positions,
        dt,
        max_gap,
        str(path),
        frames=frames,
        agent_names=ids,
        frame_numbers=numbers,
        image_height=image_height,
    )


def read_npy(path, *, dt=None, fps=None, max_gap: int = DEFAULT_MAX_GAP, agents=None, image_height=None) -> Motion:
    """Read a (T, N, D) float array saved with ``numpy.save`` (never pickled objects);
    `image_height` as in read_wide."""
    path = Path(path)
    dt = _dt(dt, fps)
    with os.fdopen(_files.open_regular(path), "rb") as handle:
        size = os.fstat(handle.fileno()).st_size
        validate.allocation(size, f"{path}: reading {size} bytes", itemsize=1)
        array = _npzfile.read_array(handle, size, source=str(path))
    if array.ndim != 3 or array.shape[2] not in (2, 3) or array.dtype.kind not in "fiu":
        raise FileFormatError(
            f"{path}: expected a numeric (T, N, D) array with D in {{2, 3}}; got {getattr(array, 'shape', '?')}"
        )
    return _motion(array, dt, max_gap, str(path), agents=agents, image_height=image_height)


def write_csv(motion: Motion, path) -> None:
    """Long format, one row per frame and agent: frame, agent, x, y[, z] (header first)."""
    frames, agents = np.meshgrid(np.arange(motion.n_frames), np.arange(motion.n_agents), indexing="ij")
    table = np.column_stack([frames.ravel(), agents.ravel(), motion.positions.reshape(-1, motion.dims)])
    header = ",".join(["frame", "agent", *"xyz"[: motion.dims]])
    with atomic_path(path) as tmp, open(tmp, "w") as handle:
        handle.write(header + "\n")
        np.savetxt(handle, table, delimiter=",", fmt=["%d", "%d"] + ["%.17g"] * motion.dims)


def write_json(motion: Motion, path) -> None:
    """{"format": "flockkit-motion", "version": 1, "dt", "frames", "agents", "dims", "positions"}
    with positions nested frame, agent, coordinate."""

    document = {
        "format": "flockkit-motion",
        "version": 1,
        "dt": motion.dt,
        "frames": motion.n_frames,
        "agents": motion.n_agents,
        "dims": motion.dims,
        "positions": motion.positions.tolist(),
    }
    with atomic_path(path) as tmp, open(tmp, "w") as handle:
        json.dump(document, handle)
