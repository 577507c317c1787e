"""OBJ sequences: one Wavefront .obj file per frame, the same faces in every one (what Blender,
Houdini and Maya write for an animated mesh they cannot describe otherwise).

A folder's .obj files, or a glob's matches, are the frames in natural order (frame2 before
frame10); each must be a regular file, and a link in a folder must stay inside it.
"""

from __future__ import annotations

import glob as globbing
import re
from pathlib import Path

import numpy as np

from .. import _files, validate
from ..errors import FileFormatError

__all__ = ["read_sequence"]

# An OBJ file says nothing of its axes or unit: y up is the convention of the tools that write
# sequences (Blender's and Maya's exporters by default); the unit is the caller's to state.
UP_AXIS = "y"


def _natural(path: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", Path(path).name)]


def _frames(pattern: str) -> list[str]:
    """The frames of an OBJ sequence in natural order: a folder's .obj files, a glob's matches,
    or one file. Each must be a regular file, and a link in a folder must stay inside it."""
    path = Path(pattern)
    if path.is_dir():
        files = [str(f) for f in path.iterdir() if f.suffix.lower() == ".obj"]
    elif path.exists():
        files = [pattern]
    else:
        files = globbing.glob(pattern)
    if not files:
        raise FileNotFoundError(f"{pattern}: no .obj files")
    for file in files:
        folder = Path(file).parent.resolve()
        if not Path(file).resolve().is_relative_to(folder):
            raise FileFormatError(f"{file}: a link that leads outside {folder}; an OBJ sequence stays in its folder")
    return sorted(files, key=_natural)


def read_sequence(pattern: str) -> tuple[np.ndarray, np.ndarray, str]:
    """(positions (T, V, 3), faces (F, 3 or 4), the first frame's name) of the OBJ sequence
    `pattern`: a folder, a glob, or one file (a path that exists is never read as a glob)."""
    files = _frames(pattern)
    positions, faces, known = None, None, None
    for t, file in enumerate(files):
        points, polygons, known = _read_obj(file, known)
        if faces is None:
            faces, first = polygons, file
            validate.allocation(len(files) * points.size, f"{pattern}: {len(files)} frames of {len(points)} vertices")
            positions = np.empty((len(files), *points.shape))
        elif len(points) != positions.shape[1] or not np.array_equal(polygons, faces):
            raise FileFormatError(
                f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
                f"{positions.shape[1]} and {len(faces)}); an OBJ sequence keeps one topology"
            )
        positions[t] = points
    return positions, faces, Path(files[0]).stem


_MAX_VERTEX = 2**40  # far above any file's vertex count, far below numpy's int64


def _read_obj(file, known=None) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """The vertices (V, 3) and faces (F, 3 or 4) of one OBJ file, and what a later frame of the
    sequence may reuse: the text of its face lines, its faces and whether that text holds a minus
    (None until a frame is plain ASCII).

    One compiled pass over the bytes (:func:`_scan`) reads the vertices and compares the face
    lines with `known`'s (an earlier frame's); where they are the same text and use no relative
    indices, the faces are those. Anything else (another face text, the first frame, a field that
    is not a plain decimal number, a byte outside plain ASCII) goes through the line-by-line
    parser, whose errors name the line."""
    data = _files.read_bytes(file)
    buffer = np.frombuffer(data, dtype=np.uint8)
    reused = known is not None and not known[2]
    status, points, hard, face_text = _scanner()(buffer, known[0] if reused else _NO_FACES, reused)
    if status == _SAME_FACES and _read_hard(buffer, points.reshape(-1), hard):
        return points, known[1], known
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{Path(file)}: not UTF-8 text (byte {exc.start})") from None
    careful, faces = _parse_obj(file, text)
    if status == _BAIL:  # no face text to go by: an earlier frame's still holds
        return careful, faces, known
    return careful, faces, (face_text, faces, bool(np.any(face_text == ord("-"))))


def _read_hard(buffer, flat, hard) -> bool:
    """Write into `flat` the numbers _scan left (rows of flat index, first byte, end), read by
    numpy's string-to-float cast, which rounds correctly as Python's float does (at most
    HARD_WIDTH characters each, the rest by float itself); whether they are all finite."""
    if not len(hard):
        return True
    index, first, stop = hard.T
    short = stop - first <= HARD_WIDTH
    width = int((stop - first)[short].max(initial=1))
    columns = np.arange(width)
    chars = buffer[np.minimum(first[short, None] + columns, len(buffer) - 1)]
    chars[columns >= (stop - first)[short, None]] = 0  # a bytes string ends at its first NUL
    flat[index[short]] = np.ascontiguousarray(chars).view(f"S{width}").ravel().astype(np.float64)
    for k, a, b in hard[~short].tolist():
        flat[k] = float(buffer[a:b].tobytes())
    return bool(np.isfinite(flat[index]).all())


# Characters at most of a number read by numpy's cast (longer ones, rare, by Python's float).
HARD_WIDTH = 40
# What _scan found: the vertices read and the face lines those of `known`; the vertices read and
# the face lines' text; nothing to go by (the line-by-line parser must read the file).
_SAME_FACES, _FACE_TEXT, _BAIL = 0, 1, 2
_NO_FACES = np.zeros(0, dtype=np.uint8)
# The largest mantissa a decimal number may have for _scan to round it on its own (Clinger's
# fast path: it and 10**e, |e| <= 22, are exact doubles, so one product or quotient rounds once,
# as a correctly rounded reading does); other numbers (repr's 17 digits) are left to Python.
_EXACT_MANTISSA = 2**53
_POWERS = 10.0 ** np.arange(23)


def _scanner():
    """:func:`_scan`, compiled by numba on first use (and cached on disk; bounds checked, as the
    bytes are untrusted). It is compiled from this module's source, not from the function's
    bytecode, which a coverage-guided fuzzer (atheris) rewrites with calls numba cannot compile."""
    global _COMPILED
    if _COMPILED is None:
        import types

        import numba

        try:
            code = compile(Path(__file__).read_text(encoding="utf-8"), __file__, "exec")
        except OSError:  # no source beside the module: its own bytecode
            function = _scan
        else:
            scan = next(c for c in code.co_consts if isinstance(c, types.CodeType) and c.co_name == "_scan")
            function = types.FunctionType(scan, globals(), "_scan")
            function.__module__, function.__qualname__, function.__doc__ = __name__, "_scan", _scan.__doc__
        _COMPILED = numba.njit(cache=True, nogil=True, boundscheck=True)(function)
    return _COMPILED


_COMPILED = None


def _scan(data, known, compare):
    """One pass over an OBJ file's bytes: (status, vertices (V, 3), hard numbers (H, 3), face text).

    Lines are split at \\n and \\r and fields at spaces and tabs, as the line-by-line parser
    splits plain ASCII; any other control character or a byte above 126 gives up (_BAIL). A line
    whose first field is ``v`` must hold three plain decimal numbers (``[+-] digits [. digits]
    [e [+-] digits]``, a digit in the mantissa), else it gives up; the rest of the line is
    ignored, as that parser ignores it. A number is read here where Clinger's fast path rounds it
    exactly (mantissa <= 2**53, |exponent| <= 22: ``%.6f`` and the like); each other one is left
    as a row (flat index into the vertices, first byte, end) of the hard numbers for Python's
    float. The text of the ``f`` lines (each from its first index to its end, joined by \\n) is
    compared with `known` when `compare` (_SAME_FACES if equal, else _FACE_TEXT), else returned."""
    n = len(data)
    points = np.empty((max(16, n // 64), 3))
    count = 0
    hard = np.empty((16, 3), dtype=np.int64)
    n_hard = 0
    text = np.empty(0 if compare else n, dtype=np.uint8)
    length = 0  # of the face text, made or compared so far
    same = True
    faces = 0
    i = 0
    while i < n:
        c = data[i]
        if c == 10 or c == 13:
            i += 1
            continue
        while i < n and (data[i] == 32 or data[i] == 9):
            i += 1
        if i >= n:
            break
        c = data[i]
        if c == 10 or c == 13:
            continue
        kind = 0  # the line's first field: 1 "v", 2 "f", 0 another
        if (c == 118 or c == 102) and (
            i + 1 >= n or (data[i + 1] == 32 or data[i + 1] == 9) or data[i + 1] == 10 or data[i + 1] == 13
        ):
            kind = 1 if c == 118 else 2
            i += 1
        if kind == 1:
            if count == len(points):
                grown = np.empty((2 * count, 3))
                grown[:count] = points
                points = grown
            for axis in range(3):
                while i < n and (data[i] == 32 or data[i] == 9):
                    i += 1
                first = i
                negative = False
                if i < n and (data[i] == 43 or data[i] == 45):
                    negative = data[i] == 45
                    i += 1
                mantissa, digits, significant, scale = 0, 0, 0, 0
                while i < n and 48 <= data[i] <= 57:
                    if mantissa or data[i] != 48:
                        significant += 1
                        if significant <= 18:
                            mantissa = mantissa * 10 + (data[i] - 48)
                        else:
                            scale += 1
                    digits += 1
                    i += 1
                if i < n and data[i] == 46:
                    i += 1
                    while i < n and 48 <= data[i] <= 57:
                        if mantissa or data[i] != 48:
                            significant += 1
                            if significant <= 18:
                                mantissa = mantissa * 10 + (data[i] - 48)
                                scale -= 1
                        else:
                            scale -= 1
                        digits += 1
                        i += 1
                if digits == 0:
                    return _BAIL, points[:0], hard[:0], text[:0]
                if i < n and (data[i] == 101 or data[i] == 69):
                    i += 1
                    sign = 1
                    if i < n and (data[i] == 43 or data[i] == 45):
                        sign = -1 if data[i] == 45 else 1
                        i += 1
                    exponent, exponent_digits = 0, 0
                    while i < n and 48 <= data[i] <= 57:
                        if exponent < 100_000:
                            exponent = exponent * 10 + (data[i] - 48)
                        exponent_digits += 1
                        i += 1
                    if exponent_digits == 0:
                        return _BAIL, points[:0], hard[:0], text[:0]
                    scale += sign * exponent
                if i < n and not ((data[i] == 32 or data[i] == 9) or data[i] == 10 or data[i] == 13):
                    return _BAIL, points[:0], hard[:0], text[:0]  # more in the field: the careful parser judges it
                if mantissa == 0:
                    value = 0.0
                elif significant > 18 or mantissa > _EXACT_MANTISSA or scale > 22 or scale < -22:
                    if n_hard == len(hard):
                        more = np.empty((2 * n_hard, 3), dtype=np.int64)
                        more[:n_hard] = hard
                        hard = more
                    hard[n_hard, 0], hard[n_hard, 1], hard[n_hard, 2] = 3 * count + axis, first, i
                    n_hard += 1
                    value = 0.0
                elif scale >= 0:
                    value = mantissa * _POWERS[scale]
                else:
                    value = mantissa / _POWERS[-scale]
                points[count, axis] = -value if negative else value
            count += 1
        elif kind == 2:
            while i < n and (data[i] == 32 or data[i] == 9):
                i += 1
            if faces:
                if compare:
                    same = same and length < len(known) and known[length] == 10
                else:
                    text[length] = 10
                length += 1
            faces += 1
            while i < n and data[i] != 10 and data[i] != 13:
                c = data[i]
                if c > 126 or (c < 32 and c != 9):
                    return _BAIL, points[:0], hard[:0], text[:0]
                if compare:
                    same = same and length < len(known) and known[length] == c
                else:
                    text[length] = c
                length += 1
                i += 1
        while i < n and data[i] != 10 and data[i] != 13:  # the rest of the line: plain ASCII or tabs
            c = data[i]
            if c > 126 or (c < 32 and c != 9):
                return _BAIL, points[:0], hard[:0], text[:0]
            i += 1
    if count == 0:
        return _BAIL, points[:0], hard[:0], text[:0]
    if compare:
        status = _SAME_FACES if same and length == len(known) else _FACE_TEXT
        return status, points[:count], hard[:n_hard], text[:0]
    return _FACE_TEXT, points[:count], hard[:n_hard], text[:length]


def _parse_obj(file, text: str) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) and faces (F, 3 or 4) of one OBJ file's text: ``v x y z`` lines (a
    fourth coordinate or vertex colours after them are ignored) and ``f`` lines of 1-based or
    negative (relative) indices; other lines are ignored."""
    points, polygons = [], []
    for number_, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields or fields[0] not in ("v", "f"):
            continue
        try:
            if fields[0] == "v":
                if len(fields) < 4:
                    raise ValueError
                points.append([float(v) for v in fields[1:4]])
                continue
            corners = [int(f.split("/")[0]) for f in fields[1:]]
            if len(corners) < 3 or 0 in corners:
                raise ValueError
        except ValueError:
            raise FileFormatError(
                f"{file}, line {number_}: not an OBJ vertex (v x y z) or face (f and 3 or more vertex numbers from 1, "
                f"or negative ones): {line.strip()[:80]!r}"
            ) from None
        corners = [c - 1 if c > 0 else len(points) + c for c in corners]  # 1-based, or relative
        if min(corners) < 0 or max(corners) > _MAX_VERTEX:
            raise FileFormatError(f"{file}, line {number_}: a face refers to a vertex that no OBJ file can hold")
        if len(corners) in (3, 4):
            polygons.append(corners)
        else:
            polygons += [[corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1)]
    if not points:
        raise FileFormatError(f"{file}: no vertices (not an OBJ file?)")
    points = np.array(points, dtype=float)
    if not np.all(np.isfinite(points)):
        raise FileFormatError(f"{file}: vertices must have finite coordinates")
    triangles = [p for p in polygons if len(p) == 3]
    quads = [p for p in polygons if len(p) == 4]
    if triangles and quads:  # one face width per mesh: split the quads
        triangles += [q[:3] for q in quads] + [[q[0], q[2], q[3]] for q in quads]
        quads = []
    faces = np.array(quads or triangles or np.zeros((0, 3)), dtype=np.int64).reshape(-1, 4 if quads else 3)
    if len(faces) and faces.max() >= len(points):
        raise FileFormatError(f"{file}: a face refers to vertex {faces.max() + 1}; the file has {len(points)}")
    return points, faces
