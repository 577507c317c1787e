"""A BVH (Biovision hierarchy) reader: the joint tree with offsets and channels in any order, end
sites as joints, and the motion as one clip.

Each joint's rotation is its rotation channels applied in the order they are listed (``Zrotation
Yrotation Xrotation`` is R = Rz Ry Rx, in degrees), its translation its OFFSET plus any position
channels, as Blender's importer reads them.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .. import _files, rigid, validate
from ..errors import FileFormatError

# BVH files say nothing of their axes or unit: y up is the format's convention (Biovision's,
# Blender's importer's), and the unit is unstated (motion-capture exports use centimetres,
# inches or other scales), so the reader reports no unit and its caller states one.
UP_AXIS = "y"

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
_CHANNEL = re.compile(r"^([XYZ])(position|rotation)$", re.IGNORECASE)


def _tokens(text: str):
    """(token, line number) for every whitespace-separated token."""
    for number, line in enumerate(text.splitlines(), 1):
        for token in line.split():
            yield token, number


def read(path):
    """(joint names, parents, rest offsets (J, 3), frame time, local rotations (T, J, 4),
    local translations (T, J, 3)) of the BVH file `path`."""
    path = Path(path)
    text = _files.read_text(path)
    head, marker, motion = text.partition("MOTION")
    if not head.lstrip().startswith("HIERARCHY") or not marker:
        raise FileFormatError(f"{path}: not a BVH file (it needs a HIERARCHY section, then MOTION)")
    names, parents, offsets, channels = _hierarchy(path, list(_tokens(head))[1:])
    if not channels:
        raise FileFormatError(f"{path}: the HIERARCHY has no CHANNELS, so nothing in the file moves")
    motion_line = head.count("\n") + 1
    lines = motion.split("\n", 3)
    try:
        frames_line, time_line = lines[1].split(), lines[2].split()
        if frames_line[0] != "Frames:" or time_line[:2] != ["Frame", "Time:"] or len(time_line) != 3:
            raise ValueError
        n_frames, frame_time = int(frames_line[1]), float(time_line[2])
    except (ValueError, IndexError):
        raise FileFormatError(
            f"{path}: line {motion_line + 1}: MOTION must be followed by 'Frames: N' and 'Frame Time: seconds'"
        ) from None
    if n_frames < 1 or not np.isfinite(frame_time) or frame_time <= 0:
        raise FileFormatError(f"{path}: line {motion_line + 1}: needs at least one frame and a positive frame time")
    width = len(channels)
    tokens = lines[3].split() if len(lines) > 3 else []
    if len(tokens) != n_frames * width:  # checked before any number is made: the count comes from the file
        raise FileFormatError(
            f"{path}: the motion has {len(tokens)} values; {n_frames} frames of {width} channels need "
            f"{n_frames * width} (truncated?)"
        )
    validate.allocation(n_frames * len(names) * 12, f"{path}: {n_frames} frames of {len(names)} joints")
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError as exc:
        raise FileFormatError(f"{path}: the motion data has a value that is not a number: {exc}") from None
    if not np.all(np.isfinite(values)):
        raise FileFormatError(f"{path}: the motion data has values that are not finite")
    values = values.reshape(n_frames, width)
    j = len(names)
    rotations = np.zeros((n_frames, j, 4))
    rotations[..., 3] = 1.0
    translations = np.broadcast_to(offsets, (n_frames, j, 3)).copy()
    for column, (joint, kind, axis) in enumerate(channels):
        if kind == "position":
            translations[:, joint, "XYZ".index(axis)] += values[:, column]
        else:
            half = np.radians(values[:, column]) / 2
            turn = np.concatenate([np.sin(half)[:, None] * _AXES[axis], np.cos(half)[:, None]], axis=1)
            rotations[:, joint] = rigid.quaternion_product(rotations[:, joint], turn)
    return names, np.array(parents), np.array(offsets), frame_time, rotations, translations


def _hierarchy(path, tokens):
    names, parents, offsets, channels = [], [], [], []
    taken: set[str] = set()
    stack: list[int] = []
    position = 0

    def take(expected=None):
        nonlocal position
        if position >= len(tokens):
            raise FileFormatError(f"{path}: the HIERARCHY ends early (truncated?)")
        token, line = tokens[position]
        position += 1
        if expected is not None and token != expected:
            raise FileFormatError(f"{path}: line {line}: expected {expected!r}, found {token!r}")
        return token, line

    def numbers(count, what):
        found = []
        for _ in range(count):
            token, line = take()
            try:
                found.append(float(token))
            except ValueError:
                raise FileFormatError(f"{path}: line {line}: {what} needs {count} numbers; found {token!r}") from None
        return found

    while position < len(tokens):
        token, line = take()
        if token in ("ROOT", "JOINT"):
            if (token == "ROOT") != (not stack):
                raise FileFormatError(f"{path}: line {line}: {token} where a {'JOINT' if stack else 'ROOT'} belongs")
            name, _ = take()
            if name in taken:
                raise FileFormatError(f"{path}: line {line}: joint {name!r} appears twice")
            take("{")
            take("OFFSET")
            offset = numbers(3, "OFFSET")
            index = len(names)
            names.append(name)
            taken.add(name)
            parents.append(stack[-1] if stack else -1)
            offsets.append(offset)
            stack.append(index)
            if position < len(tokens) and tokens[position][0] == "CHANNELS":
                take()
                count_token, count_line = take()
                if not (count_token.isascii() and count_token.isdigit()):
                    raise FileFormatError(f"{path}: line {count_line}: CHANNELS needs a count; found {count_token!r}")
                for _ in range(int(count_token)):
                    channel, channel_line = take()
                    match = _CHANNEL.match(channel)
                    if not match:
                        raise FileFormatError(f"{path}: line {channel_line}: unknown channel {channel!r}")
                    channels.append((index, match.group(2).lower(), match.group(1).upper()))
        elif token == "End":
            take("Site")
            if not stack:
                raise FileFormatError(f"{path}: line {line}: an End Site outside a joint")
            take("{")
            take("OFFSET")
            offset = numbers(3, "OFFSET")
            take("}")
            parent = stack[-1]
            name, k = f"{names[parent]}_end", 1
            while name in taken:
                k += 1
                name = f"{names[parent]}_end{k}"
            names.append(name)
            taken.add(name)
            parents.append(parent)
            offsets.append(offset)
        elif token == "}":
            if not stack:
                raise FileFormatError(f"{path}: line {line}: '}}' closes nothing")
            stack.pop()
        else:
            raise FileFormatError(f"{path}: line {line}: unexpected {token!r} in the HIERARCHY")
    if stack:
        raise FileFormatError(f"{path}: the HIERARCHY leaves {len(stack)} joint(s) open (a missing '}}')")
    if not names:
        raise FileFormatError(f"{path}: the HIERARCHY has no ROOT")
    return names, parents, offsets, channels
