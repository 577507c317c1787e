"""OBJ sequences: one Wavefront .obj file per frame, the same faces in every one (what Blender,
Houdini and Maya write for an animated mesh they cannot describe otherwise).

A folder's .obj files, or a glob's matches, are the frames in natural order (frame2 before
frame10); each must be a regular file, and a link in a folder must stay inside it.
"""

from __future__ import annotations

import glob as globbing
import math
import os
import re
from concurrent.futures import ThreadPoolExecutor
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
    `pattern`: a folder, a glob, or one file (a path that exists is never read as a glob).

    Every file is asked into the system's cache first (:func:`_read_ahead`). The first frame is
    read on its own; the others are read by a pool of threads (as many as
    numba's, ``numba.get_num_threads()``), each file by one thread straight into its frame of the
    output, with the compiled pass (:func:`_scan`) that reads the numbers as Python's float and
    int read them and checks that the faces are the first frame's. A file that pass does not
    read whole goes through the line-by-line parser, whose errors name the file and the line;
    where several frames are bad, the error is the first one's."""
    files = _frames(pattern)
    _read_ahead(files)
    points, faces, known = _read_first(files[0])
    validate.allocation(len(files) * points.size, f"{pattern}: {len(files)} frames of {len(points)} vertices")
    positions = np.empty((len(files), *points.shape))
    positions[0] = points

    def read(t):
        _read_later(files[t], files[0], positions[t], faces, known)

    import numba

    later = range(1, len(files))
    threads = min(numba.get_num_threads(), len(later))
    if threads > 1:
        with ThreadPoolExecutor(threads) as pool:
            for _ in pool.map(read, later):  # in frame order: the first bad frame's error is raised
                pass
    else:
        for t in later:
            read(t)
    return positions, faces, Path(files[0]).stem


def _read_ahead(files) -> None:
    """Ask the system to read every frame's file into its cache now (``posix_fadvise`` with
    WILLNEED, where the system has it), so the disk reads the later frames while the first ones
    are parsed. Only regular files are asked for; anything else is left to the readers, which
    refuse it."""
    advise = getattr(os, "posix_fadvise", None)
    if advise is None:
        return
    for file in files:
        try:
            fd = _files.open_regular(file)
        except (OSError, FileFormatError):
            continue
        try:
            advise(fd, 0, 0, os.POSIX_FADV_WILLNEED)
        except OSError:
            pass
        finally:
            os.close(fd)


_MAX_VERTEX = 2**40  # far above any file's vertex count, far below numpy's int64
# What the compiled pass found: the file read, or a file the line-by-line parser must read (a
# field that is not a plain decimal number, a byte outside plain ASCII, another topology than
# the first frame's, or anything that parser would refuse).
_READ, _CAREFUL = 0, 1
_NO_CORNERS = np.zeros(0, dtype=np.int64)


def _read_first(file) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """The vertices (V, 3) and faces of the first frame, and the corners and corner counts of
    its faces as the compiled pass reads them (None where that pass could not read it: later
    frames then go through the line-by-line parser too)."""
    data = _files.read_bytes(file)
    buffer = np.frombuffer(data, dtype=np.uint8)
    scan, powers = _compiled()
    status, points, corners, counts = scan(buffer, np.empty((max(16, len(data) // 64), 3)), _NO_CORNERS,
                                           _NO_CORNERS, False, *powers)  # fmt: skip
    if status == _READ:
        return points, _faces(corners, counts), (corners, counts)
    return (*_parse_obj(file, _text(file, data)), None)


def _read_later(file, first, out: np.ndarray, faces: np.ndarray, known) -> None:
    """Read the frame `file` into `out` (V, 3); FileFormatError naming it if it is not an OBJ
    file or its topology differs from `first`'s (`faces`)."""
    data = _files.read_bytes(file)
    if known is not None:
        scan, powers = _compiled()
        if scan(np.frombuffer(data, dtype=np.uint8), out, *known, True, *powers)[0] == _READ:
            return
    points, polygons = _parse_obj(file, _text(file, data))
    if len(points) != len(out) or not np.array_equal(polygons, faces):
        raise FileFormatError(
            f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
            f"{len(out)} and {len(faces)}); an OBJ sequence keeps one topology"
        )
    out[...] = points


def _text(file, data: bytes) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{Path(file)}: not UTF-8 text (byte {exc.start})") from None


def _faces(corners: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The faces (F, 3 or 4) of polygons given as their corners, one after another, and their
    corner counts, as :func:`_parse_obj` makes them: triangles and quads kept, larger polygons cut
    into fans of triangles, and the quads cut in two where the mesh also has triangles."""
    starts = np.cumsum(counts) - counts
    quads = corners[starts[counts == 4, None] + np.arange(4)]
    fans = np.where(counts == 4, 0, counts - 2)  # triangles of each other polygon, in file order
    polygon = np.repeat(np.arange(len(counts)), fans)
    step = np.arange(len(polygon)) - np.repeat(np.cumsum(fans) - fans, fans)
    first = starts[polygon]
    triangles = np.stack([corners[first], corners[first + step + 1], corners[first + step + 2]], axis=1)
    if len(triangles) and len(quads):
        return np.concatenate([triangles, quads[:, :3], quads[:, [0, 2, 3]]])
    return quads if len(quads) else triangles


def _powers_of_five() -> tuple[np.ndarray, np.ndarray]:
    """The 128 leading bits of 5**q for q in -342..308 (for q < 0, of its reciprocal, rounded up),
    as (high, low) 64-bit words: the table of the Eisel-Lemire conversion (Lemire, "Number parsing
    at a gigabyte per second", Software: Practice and Experience 51(8), 2021; the rounding of the
    negative powers as in Mushtak and Lemire, "Fast number parsing without fallback", 2023, whose
    proof makes 19 or fewer digits always exact)."""
    high, low = np.empty(651, dtype=np.uint64), np.empty(651, dtype=np.uint64)
    for k, q in enumerate(range(-342, 309)):
        if q >= 0:
            value = 5**q
        else:
            power = 5**-q
            bits = (power - 1).bit_length()  # the smallest z with 2**z >= power
            value = 2 ** (bits + 127 if q >= -17 else 2 * bits + 64) // power + 1
        length = value.bit_length()
        value = value << (128 - length) if length < 128 else value >> (length - 128)
        high[k], low[k] = value >> 64, value & (2**64 - 1)
    return high, low


def _compiled():
    """(:func:`_scan` and its helpers compiled by numba on first use and cached on disk, the
    table of powers of five). They are compiled from this module's source, not from the
    functions' bytecode, which a coverage-guided fuzzer (atheris) rewrites with calls numba
    cannot compile; the bounds are checked, as the bytes are untrusted."""
    global _COMPILED
    if _COMPILED is None:
        import types

        import numba

        names = ("_multiply", "_leading_zeros", "_eisel_lemire", "_number", "_scan")
        namespace = dict(globals())
        try:
            code = compile(Path(__file__).read_text(encoding="utf-8"), __file__, "exec")
            found = {c.co_name: c for c in code.co_consts if isinstance(c, types.CodeType) and c.co_name in names}
        except OSError:  # no source beside the module: the functions' own bytecode
            found = {name: globals()[name].__code__ for name in names}
        for name in names:
            function = types.FunctionType(found[name], namespace, name)
            function.__module__, function.__qualname__ = __name__, name
            function.__doc__ = globals()[name].__doc__
            inline = "always" if name == "_number" else "never"  # inlined into its loop: 10% faster
            namespace[name] = numba.njit(cache=True, nogil=True, boundscheck=True, inline=inline)(function)
        _COMPILED = namespace["_scan"], _powers_of_five()
    return _COMPILED


_COMPILED = None
# Constants of the compiled pass, as numba reads them (64-bit unsigned words where it computes
# with them).
_U32, _U64_MASK32 = np.uint64(32), np.uint64(0xFFFFFFFF)
_U1, _U63 = np.uint64(1), np.uint64(63)
_PRECISION_MASK = np.uint64(0xFFFFFFFFFFFFFFFF >> 55)  # the bits below a double's 53 and 2 more
# Clinger's fast path: a mantissa of at most 2**53 and 10**e, |e| <= 22, are exact doubles, so
# one product or quotient rounds once, as a correctly rounded reading does.
_EXACT_MANTISSA = np.uint64(2**53)
_POWERS = 10.0 ** np.arange(23)
# Significant digits a mantissa keeps (the rest decide only whether it is exact): 19 fit a 64-bit
# word, and Eisel and Lemire's conversion is exact for all of them.
_KEPT_DIGITS = 19
_U0, _U10 = np.uint64(0), np.uint64(10)


def _multiply(a, b):
    """The 128-bit product of two 64-bit words, as (high, low) words."""
    a0, a1, b0, b1 = a & _U64_MASK32, a >> _U32, b & _U64_MASK32, b >> _U32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    middle = (p00 >> _U32) + (p01 & _U64_MASK32) + (p10 & _U64_MASK32)
    return p11 + (p01 >> _U32) + (p10 >> _U32) + (middle >> _U32), (middle << _U32) | (p00 & _U64_MASK32)


def _leading_zeros(w):
    """The leading zero bits of a nonzero 64-bit word."""
    count = 0
    for bits in (32, 16, 8, 4, 2, 1):
        if w >> np.uint64(64 - bits) == 0:
            count += bits
            w = w << np.uint64(bits)
    return count


def _eisel_lemire(mantissa, q, power_high, power_low):
    """The double nearest mantissa * 10**q (mantissa a nonzero 64-bit word of at most 19
    digits), ties to even, as Python's float reads it: Eisel and Lemire's conversion (see
    :func:`_powers_of_five`)."""
    if q < -342:
        return 0.0
    if q > 308:
        return np.inf
    w = mantissa
    shifted = _leading_zeros(w)
    w = w << np.uint64(shifted)
    index = q + 342
    high, low = _multiply(w, power_high[index])
    if high & _PRECISION_MASK == _PRECISION_MASK:  # the next 64 bits of the power may carry into these
        more = _multiply(w, power_low[index])[0]
        low = low + more
        if more > low:
            high = high + _U1
    upper = np.int64(high >> _U63)
    shift = np.uint64(upper + 9)
    bits = high >> shift
    exponent = (((152170 + 65536) * q) >> 16) + 63 + upper - shifted + 1023
    if exponent <= 0:  # a subnormal, or zero
        if 1 - exponent >= 64:
            return 0.0
        bits = bits >> np.uint64(1 - exponent)
        bits = (bits + (bits & _U1)) >> _U1
        return math.ldexp(float(bits), -1074)
    if low <= _U1 and -4 <= q <= 23 and bits & np.uint64(3) == _U1 and bits << shift == high:
        bits = bits & ~_U1  # exactly halfway: to even
    bits = (bits + (bits & _U1)) >> _U1
    if bits >= np.uint64(2**53):
        bits = np.uint64(2**52)
        exponent += 1
    if exponent >= 2047:
        return np.inf
    return math.ldexp(float(bits), exponent - 1075)


def _number(data, i, n, power_high, power_low):
    """The number whose field starts at data[i]: (the index after it, its value, whether it is a
    plain decimal number ``[+-] digits [. digits] [(e|E) [+-] digits]`` with a digit in the
    mantissa, ending at a blank or a line's end, whose value Python's float gives finite and
    this reads exactly). Digits are read as integers; Clinger's fast path rounds the easy ones,
    Eisel and Lemire's conversion the others (17 digits, large exponents); a mantissa of more
    than 19 digits is read as its first 19 and, where it has more nonzero ones, as the next
    mantissa too, and accepted where both give the same double."""
    negative = False
    if i < n and (data[i] == 43 or data[i] == 45):
        negative = data[i] == 45
        i += 1
    mantissa, kept, scale, digits, inexact = _U0, 0, 0, 0, False
    while i < n and data[i] == 48:  # leading zeros
        digits += 1
        i += 1
    while i < n:
        digit = np.int64(data[i]) - 48
        if digit < 0 or digit > 9:
            break
        if kept < _KEPT_DIGITS:
            mantissa = mantissa * _U10 + np.uint64(digit)
            kept += 1
        else:
            scale += 1
            inexact = inexact or digit != 0
        digits += 1
        i += 1
    if i < n and data[i] == 46:
        i += 1
        if kept == 0:  # zeros after the point, before the first significant digit
            while i < n and data[i] == 48:
                scale -= 1
                digits += 1
                i += 1
        while i < n:
            digit = np.int64(data[i]) - 48
            if digit < 0 or digit > 9:
                break
            if kept < _KEPT_DIGITS:
                mantissa = mantissa * _U10 + np.uint64(digit)
                kept += 1
                scale -= 1
            else:
                inexact = inexact or digit != 0
            digits += 1
            i += 1
    if digits == 0:
        return i, 0.0, False
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
            return i, 0.0, False
        scale += sign * exponent
    if i < n and not (data[i] == 32 or data[i] == 9 or data[i] == 10 or data[i] == 13):
        return i, 0.0, False  # more in the field: the careful parser judges it
    if mantissa == 0:
        value = 0.0
    elif not inexact and mantissa <= _EXACT_MANTISSA and -22 <= scale <= 22:
        value = float(mantissa) * _POWERS[scale] if scale >= 0 else float(mantissa) / _POWERS[-scale]
    else:
        value = _eisel_lemire(mantissa, scale, power_high, power_low)
        if inexact and _eisel_lemire(mantissa + _U1, scale, power_high, power_low) != value:
            return i, 0.0, False
        if value == np.inf:
            return i, 0.0, False
    return i, -value if negative else value, True


def _scan(data, out, known_corners, known_counts, compare, power_high, power_low):
    """One pass over an OBJ file's bytes: (status, vertices (V, 3), corners, corner counts).

    Lines are split at \\n and \\r and fields at spaces and tabs, as the line-by-line parser
    splits plain ASCII (a leading UTF-8 byte order mark skipped, as it drops it); any other
    control character or a byte above 126 gives up (_CAREFUL). A line whose first field is ``v``
    must hold three numbers :func:`_number` reads (the rest of the line is ignored, as that parser
    ignores it), and one whose first field is ``f`` three or more corners (``[+-] digits``,
    optionally followed by ``/`` and anything; negative ones count back from the vertices so
    far), else it gives up. Vertices are written into `out` (grown where it is full, unless
    `compare`). Without `compare` the faces' corners and counts are returned; with it, the
    vertices must fill `out` exactly and the faces be `known_corners` and `known_counts`, else it
    gives up."""
    n = len(data)
    points = out
    count = 0
    corners = np.empty(0 if compare else max(16, n // 8), dtype=np.int64)
    counts = np.empty(0 if compare else max(16, n // 32), dtype=np.int64)
    n_corners, n_faces, largest = 0, 0, -1
    i = 3 if n >= 3 and data[0] == 0xEF and data[1] == 0xBB and data[2] == 0xBF else 0
    while i < n:
        while i < n and (data[i] == 32 or data[i] == 9):
            i += 1
        if i >= n:
            break
        c = data[i]
        if c == 10 or c == 13:
            i += 1
            continue
        kind = 0  # the line's first field: 1 "v", 2 "f", 0 another
        if (c == 118 or c == 102) and (
            i + 1 >= n or data[i + 1] == 32 or data[i + 1] == 9 or data[i + 1] == 10 or data[i + 1] == 13
        ):
            kind = 1 if c == 118 else 2
            i += 1
        if kind == 1:
            if count == len(points):
                if compare:
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
                grown = np.empty((2 * count, 3))
                grown[:count] = points
                points = grown
            for axis in range(3):
                while i < n and (data[i] == 32 or data[i] == 9):
                    i += 1
                i, value, good = _number(data, i, n, power_high, power_low)
                if not good:
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
                points[count, axis] = value
            count += 1
        elif kind == 2:
            own = 0
            while True:
                while i < n and (data[i] == 32 or data[i] == 9):
                    i += 1
                if i >= n or data[i] == 10 or data[i] == 13:
                    break
                negative = False
                if data[i] == 43 or data[i] == 45:
                    negative = data[i] == 45
                    i += 1
                index, digits = 0, 0
                while i < n and 48 <= data[i] <= 57:
                    if index <= _MAX_VERTEX:
                        index = index * 10 + (data[i] - 48)
                    digits += 1
                    i += 1
                if i < n and data[i] == 47:  # "/" and texture or normal numbers, which are ignored
                    while i < n and 32 < data[i] <= 126:
                        i += 1
                if digits == 0 or index == 0 or index > _MAX_VERTEX:
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
                if i < n and not (data[i] == 32 or data[i] == 9 or data[i] == 10 or data[i] == 13):
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
                corner = count - index if negative else index - 1
                if corner < 0:
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
                largest = max(largest, corner)
                if compare:
                    if n_corners >= len(known_corners) or known_corners[n_corners] != corner:
                        return _CAREFUL, points[:0], corners[:0], counts[:0]
                else:
                    if n_corners == len(corners):
                        more = np.empty(2 * n_corners, dtype=np.int64)
                        more[:n_corners] = corners
                        corners = more
                    corners[n_corners] = corner
                n_corners += 1
                own += 1
            if own < 3:
                return _CAREFUL, points[:0], corners[:0], counts[:0]
            if compare:
                if n_faces >= len(known_counts) or known_counts[n_faces] != own:
                    return _CAREFUL, points[:0], corners[:0], counts[:0]
            else:
                if n_faces == len(counts):
                    more = np.empty(2 * n_faces, dtype=np.int64)
                    more[:n_faces] = counts
                    counts = more
                counts[n_faces] = own
            n_faces += 1
        while i < n and data[i] != 10 and data[i] != 13:  # the rest of the line: plain ASCII or tabs
            c = data[i]
            if c > 126 or (c < 32 and c != 9):
                return _CAREFUL, points[:0], corners[:0], counts[:0]
            i += 1
    if count == 0 or largest >= count:
        return _CAREFUL, points[:0], corners[:0], counts[:0]
    if compare and (count != len(points) or n_faces != len(known_counts) or n_corners != len(known_corners)):
        return _CAREFUL, points[:0], corners[:0], counts[:0]
    return _READ, points[:count], corners[:n_corners], counts[:n_faces]


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
