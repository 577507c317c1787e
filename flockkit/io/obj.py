"""OBJ sequences: one Wavefront .obj file per frame, the same faces in every one (what Blender,
Houdini and Maya write for an animated mesh they cannot describe otherwise).

A folder's .obj files, or a glob's matches, are the frames in natural order (frame2 before
frame10); each must be a regular file, and a link in a folder must stay inside it.
"""

from __future__ import annotations

import glob as globbing
import os
import re
import threading
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
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", os.path.basename(path))]


def _frames(pattern: str) -> list[str]:
    """The frames of an OBJ sequence in natural order: a folder's .obj files, a glob's matches,
    or one file. Each must be a regular file, and a link in a folder must stay inside it (only
    links are resolved: any other file's name stays in its folder)."""
    path = Path(pattern)
    if path.is_dir():
        with os.scandir(path) as entries:
            found = [(entry.path, entry.is_symlink()) for entry in entries
                     if os.path.splitext(entry.name)[1].lower() == ".obj"]  # fmt: skip
    else:
        found = [(file, os.path.islink(file)) for file in ([pattern] if path.exists() else globbing.glob(pattern))]
    if not found:
        raise FileNotFoundError(f"{pattern}: no .obj files")
    for file in (file for file, link in found if link):
        folder = Path(file).parent.resolve()
        if not Path(file).resolve().is_relative_to(folder):
            raise FileFormatError(f"{file}: a link that leads outside {folder}; an OBJ sequence stays in its folder")
    return sorted((file for file, _ in found), key=_natural)


def read_sequence(pattern: str) -> tuple[np.ndarray, np.ndarray, str]:
    """(positions (T, V, 3), faces (F, 3 or 4), the first frame's name) of the OBJ sequence
    `pattern`: a folder, a glob, or one file (a path that exists is never read as a glob).

    The first frame is read while a thread asks the system to read the others into its cache
    (:func:`_read_ahead`); then they are read by a pool of threads (as many as numba's,
    ``numba.get_num_threads()``; with one, by the calling thread), each file by one thread
    straight into its frame of the output, with the compiled pass (:func:`_scan`) that reads
    the numbers as Python's float and int read them and checks that the faces are the first
    frame's (a face line that holds the first frame's bytes is not read again). A file that
    pass does not read whole goes through the line-by-line parser, whose errors name the file
    and the line; where several frames are bad, the error is the first one's."""
    import numba

    files = _frames(pattern)
    later = range(1, len(files))
    threads = max(1, min(numba.get_num_threads(), len(later)))
    with ThreadPoolExecutor(threads) as pool:
        pool.submit(_read_ahead, files[1:])
        points, faces, known = _read_first(files[0])
        validate.allocation(len(files) * points.size, f"{pattern}: {len(files)} frames of {len(points)} vertices")
        positions = np.empty((len(files), *points.shape))
        positions[0] = points
        local = threading.local()  # each thread's buffer, read into frame after frame

        def read(t):
            local.buffer = _read_later(files[t], files[0], positions[t], faces, known, getattr(local, "buffer", None))

        for _ in pool.map(read, later) if threads > 1 else map(read, later):  # in frame order: the first bad
            pass  # frame's error is raised
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
# the first frame's, or anything that parser would refuse), or an array it was given full.
_READ, _CAREFUL, _FULL = 0, 1, 2
_NO_BYTES = np.zeros(0, dtype=np.uint8)


def _read_padded(file, buffer=None) -> tuple[np.ndarray, int]:
    """(a buffer holding the bytes of the regular file `file` followed by :data:`_PAD` line ends,
    the file's length): `buffer` where it is large enough, else a new one (the size checked
    against the memory budget first), so that a thread reads frame after frame into one buffer,
    straight from the file (no bytes object, no text)."""
    fd = _files.open_regular(file)
    with os.fdopen(fd, "rb", buffering=0) as handle:
        size = os.fstat(fd).st_size
        if buffer is None or len(buffer) < size + _PAD:
            validate.allocation(size + size // 8 + _PAD, f"{file}: reading {size} bytes", itemsize=1)
            buffer = np.empty(size + size // 8 + _PAD, dtype=np.uint8)  # room for later, larger frames
        view = memoryview(buffer)
        n = 0
        while n < size:
            got = handle.readinto(view[n:size])
            if not got:
                break
            n += got
    buffer[n : n + _PAD] = _LINE_END
    return buffer, n


def _read_first(file) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """The vertices (V, 3) and faces of the first frame, and what the compiled pass compares a
    later frame with: the corners and corner counts of its faces, where their lines start, and
    its bytes with their padding (None where that pass could not read it: later frames then go
    through the line-by-line parser too)."""
    buffer, n = _read_padded(file)
    status, points, corners, counts, starts = _scan_alone(buffer, n, file)
    if status == _READ:
        return points, _faces(corners, counts), (corners, counts, starts, buffer[: n + _PAD])
    return (*_parse_obj(file, _text(file, buffer[:n].tobytes())), None)


def _scan_alone(buffer, n, file="") -> tuple:
    """:func:`_scan` of the file `file` read on its own (see :func:`_read_padded`), given room
    for its vertices, corners and faces (the room checked against the memory budget): (status,
    vertices, corners, corner counts, where each face's line starts)."""
    rows = max(16, n // 32)  # enough for "v" lines of 32 bytes and "f" lines of 3 corners of 4 bytes
    while True:
        validate.allocation(8 * rows, f"{file}: room for {rows} vertices and faces")  # 8 numbers a row
        points, corners, counts = np.empty((rows, 3)), np.empty(3 * rows, dtype=np.int64), np.empty(rows, np.int64)
        found = _compiled()(buffer, n, points, corners, counts, np.empty(rows, np.int64), _NO_BYTES, False)
        if found[0] != _FULL:
            return found
        rows *= 2  # at most n // 2 + 1 vertices, faces or corners (a byte and a blank each)


def _read_later(file, first, out: np.ndarray, faces: np.ndarray, known, buffer=None) -> np.ndarray:
    """Read the frame `file` into `out` (V, 3) through `buffer` (see :func:`_read_padded`; the
    buffer used is returned); FileFormatError naming it if it is not an OBJ file or its topology
    differs from `first`'s (`faces`)."""
    buffer, n = _read_padded(file, buffer)
    if known is not None:
        if _compiled()(buffer, n, out, *known, True)[0] == _READ:
            return buffer
    points, polygons = _parse_obj(file, _text(file, buffer[:n].tobytes()))
    if len(points) != len(out) or not np.array_equal(polygons, faces):
        raise FileFormatError(
            f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
            f"{len(out)} and {len(faces)}); an OBJ sequence keeps one topology"
        )
    out[...] = points
    return buffer


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
    """:func:`_scan` and its helpers, compiled by numba on first use and cached on disk (the
    table of powers of five, :func:`_powers_of_five`, a constant of the compiled code). They are
    compiled from this module's source, not from the functions' bytecode, which a
    coverage-guided fuzzer (atheris) rewrites with calls numba cannot compile. Numba's bounds
    checks are off: every index into the file's bytes stays inside them and their padding
    (:func:`_scan` says why), and every index into another array is checked where it is
    computed."""
    global _COMPILED
    if _COMPILED is None:
        import types

        import numba
        from numba.cpython.unsafe import numbers

        names = ("_multiply", "_eisel_lemire", "_long_digits", "_long_number", "_at", "_word", "_digit_run",
                 "_zero_bytes", "_scan")  # fmt: skip
        namespace = dict(globals())
        namespace["_leading_zeros"], namespace["_trailing_zeros"] = numbers.leading_zeros, numbers.trailing_zeros
        namespace["_FIVE_HIGH"], namespace["_FIVE_LOW"] = _powers_of_five()  # constants of the compiled code
        try:
            code = compile(Path(__file__).read_text(encoding="utf-8"), __file__, "exec")
            found = {c.co_name: c for c in code.co_consts if isinstance(c, types.CodeType) and c.co_name in names}
        except OSError:  # no source beside the module: the functions' own bytecode
            found = {name: globals()[name].__code__ for name in names}
        for name in names:
            function = types.FunctionType(found[name], namespace, name)
            function.__module__, function.__qualname__ = __name__, name
            function.__doc__ = globals()[name].__doc__
            inline = "always" if name in ("_at", "_word", "_digit_run", "_zero_bytes") else "never"  # in their loops
            namespace[name] = numba.njit(cache=True, nogil=True, boundscheck=False, inline=inline)(function)
        _COMPILED = namespace["_scan"]
    return _COMPILED


_COMPILED = None
_FIVE_HIGH = _FIVE_LOW = None  # the table of powers of five, given to the compiled code only
# Constants of the compiled pass, as numba reads them (64-bit unsigned words where it computes
# with them).
_U32, _U64_MASK32 = np.uint64(32), np.uint64(0xFFFFFFFF)
_U1, _U3, _U8, _U16, _U63 = np.uint64(1), np.uint64(3), np.uint64(8), np.uint64(16), np.uint64(63)
_PRECISION_MASK = np.uint64(0xFFFFFFFFFFFFFFFF >> 55)  # the bits below a double's 53 and 2 more
_FRACTION = np.uint64(2**52 - 1)  # a double's 52 stored bits of its mantissa
# Clinger's fast path: a mantissa of at most 2**53 and 10**e, |e| <= 22, are exact doubles, so
# one product or quotient rounds once, as a correctly rounded reading does.
_EXACT_MANTISSA = np.uint64(2**53)
_POWERS = 10.0 ** np.arange(23)
# Significant digits a mantissa keeps (the rest decide only whether it is exact): 19 fit a 64-bit
# word, and Eisel and Lemire's conversion is exact for all of them.
_KEPT_DIGITS = 19
_U0, _U10 = np.uint64(0), np.uint64(10)
# Eight bytes at a time (:func:`_digit_run`): the bytes' high and low halves, '0' in every byte,
# 6 in every byte; 10**k for the k <= 8 digits of a run.
_HIGH_HALVES, _LOW_HALVES = np.uint64(0xF0F0F0F0F0F0F0F0), np.uint64(0x0F0F0F0F0F0F0F0F)
_ZEROS, _SIXES = np.uint64(0x3030303030303030), np.uint64(0x0606060606060606)
_SECOND_BYTES = np.uint64(0x000000FF000000FF)
_TIMES_100, _TIMES_1 = np.uint64(100 + (1000000 << 32)), np.uint64(1 + (10000 << 32))
_RUN_POWERS = 10 ** np.arange(9, dtype=np.uint64)
_TEN_TO_8 = np.uint64(10**8)
# Bytes after a file's bytes in the buffer the compiled pass reads: line ends, on which every scan
# stops, so that no scan needs to test for the end (an 8-byte word read at the end stays inside).
_PAD = 16
_LINE_END = 10
# Line ends in every byte of a word, and the words :func:`_zero_bytes` works with.
_LINE_FEEDS, _RETURNS = np.uint64(0x0A0A0A0A0A0A0A0A), np.uint64(0x0D0D0D0D0D0D0D0D)
_BYTE_ONES, _BYTE_HIGHS = np.uint64(0x0101010101010101), np.uint64(0x8080808080808080)


def _leading_zeros(w):
    """The leading zero bits of a 64-bit word (64 for zero); compiled as LLVM's ctlz."""
    return 64 - int(w).bit_length()


def _trailing_zeros(w):
    """The trailing zero bits of a 64-bit word (64 for zero); compiled as LLVM's cttz."""
    w = int(w)
    return 64 if w == 0 else (w & -w).bit_length() - 1


def _multiply(a, b):
    """The 128-bit product of two 64-bit words, as (high, low) words."""
    a0, a1, b0, b1 = a & _U64_MASK32, a >> _U32, b & _U64_MASK32, b >> _U32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    middle = (p00 >> _U32) + (p01 & _U64_MASK32) + (p10 & _U64_MASK32)
    return p11 + (p01 >> _U32) + (p10 >> _U32) + (middle >> _U32), (middle << _U32) | (p00 & _U64_MASK32)


def _eisel_lemire(mantissa, q):
    """The double nearest mantissa * 10**q (mantissa a nonzero 64-bit word of at most 19
    digits), ties to even, as Python's float reads it: Eisel and Lemire's conversion (see
    :func:`_powers_of_five`), the double built from its bits."""
    if q < -342:
        return 0.0
    if q > 308:
        return np.inf
    shifted = np.int64(_leading_zeros(mantissa))
    w = mantissa << np.uint64(shifted)
    index = q + 342  # in 0..650, the table's rows
    high, low = _multiply(w, _FIVE_HIGH[index])
    if high & _PRECISION_MASK == _PRECISION_MASK:  # the next 64 bits of the power may carry into these
        more = _multiply(w, _FIVE_LOW[index])[0]
        low = low + more
        if more > low:
            high = high + _U1
    upper = np.int64(high >> _U63)
    shift = np.uint64(upper + 9)
    bits = high >> shift
    exponent = (((152170 + 65536) * q) >> 16) + 63 + upper - shifted + 1023
    if exponent <= 0:  # a subnormal, or zero: its bits are the rounded mantissa's
        if 1 - exponent >= 64:
            return 0.0
        bits = bits >> np.uint64(1 - exponent)
        bits = (bits + (bits & _U1)) >> _U1
        return np.uint64(bits).view(np.float64)
    if low <= _U1 and -4 <= q <= 23 and bits & np.uint64(3) == _U1 and bits << shift == high:
        bits = bits & ~_U1  # exactly halfway: to even
    bits = (bits + (bits & _U1)) >> _U1
    if bits >= np.uint64(2**53):
        bits = np.uint64(2**52)
        exponent += 1
    if exponent >= 2047:
        return np.inf
    return np.uint64((bits & _FRACTION) | (np.uint64(exponent) << np.uint64(52))).view(np.float64)


def _long_digits(data, i, n, mantissa, kept, scale, digits, inexact, fraction):
    """:func:`_long_number`'s run of digits from data[i] (the integer's, or the `fraction`'s):
    the first _KEPT_DIGITS significant ones kept in the mantissa, each later one counted in the
    scale (an integer's) or dropped (a fraction's), and whether any of those was not 0. Returns
    (i, mantissa, kept, scale, digits, inexact) after them."""
    while i < n:
        digit = np.int64(data[i]) - 48
        if digit < 0 or digit > 9:
            break
        if kept < _KEPT_DIGITS:
            mantissa = mantissa * _U10 + np.uint64(digit)
            kept += 1
            if fraction:
                scale -= 1
        else:
            if not fraction:
                scale += 1
            inexact = inexact or digit != 0
        digits += 1
        i += 1
    return i, mantissa, kept, scale, digits, inexact


def _long_number(data, i, n):
    """(the index after it, its value, whether it is read) of a number of more than 19
    significant digits starting at data[i], a byte at a time (data[:n] the file), in the form
    :func:`_scan` reads: the mantissa is read as its first 19 digits and, where it has more
    nonzero ones, as the next mantissa too, and accepted where both give the same double."""
    negative = False
    if i < n and (data[i] == 43 or data[i] == 45):
        negative = data[i] == 45
        i += 1
    mantissa, kept, scale, digits, inexact = _U0, 0, 0, 0, False
    while i < n and data[i] == 48:  # leading zeros
        digits += 1
        i += 1
    i, mantissa, kept, scale, digits, inexact = _long_digits(data, i, n, mantissa, kept, scale, digits, inexact, False)
    if i < n and data[i] == 46:
        i += 1
        if kept == 0:  # zeros after the point, before the first significant digit
            while i < n and data[i] == 48:
                scale -= 1
                digits += 1
                i += 1
        i, mantissa, kept, scale, digits, inexact = _long_digits(data, i, n, mantissa, kept, scale, digits, inexact,
                                                                 True)  # fmt: skip
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
        value = _eisel_lemire(mantissa, scale)
        if inexact and _eisel_lemire(mantissa + _U1, scale) != value:
            return i, 0.0, False
        if value == np.inf:
            return i, 0.0, False
    return i, -value if negative else value, True


def _word(data, i):
    """The 8 bytes at data[i] as one little-endian 64-bit word (one load: the index unsigned,
    so that no test for a negative one comes between the bytes)."""
    j = np.uint64(i)
    return (np.uint64(data[j]) | np.uint64(data[j + _U1]) << _U8 | np.uint64(data[j + np.uint64(2)]) << _U16
            | np.uint64(data[j + _U3]) << np.uint64(24) | np.uint64(data[j + np.uint64(4)]) << _U32
            | np.uint64(data[j + np.uint64(5)]) << np.uint64(40) | np.uint64(data[j + np.uint64(6)]) << np.uint64(48)
            | np.uint64(data[j + np.uint64(7)]) << np.uint64(56))  # fmt: skip


def _at(data, i):
    """data[i], i an index known not to be negative (read unsigned: no test for a negative one)."""
    return data[np.uint64(i)]


def _zero_bytes(w):
    """A word whose lowest set bit is the high bit of the first zero byte of the word `w` (no bit
    set where it has none; bits above the first may be set too)."""
    return (w - _BYTE_ONES) & ~w & _BYTE_HIGHS


def _digit_run(w):
    """(k, the number the k digits write) for the k <= 8 digits that the 8 bytes of the word `w`
    (see :func:`_word`) begin with: the first byte that is not a digit found from the bits of
    all 8 at once, and the digits converted with three multiplications (Lemire's "parse eight
    digits" of fast_float), the bytes after them shifted out and zeros shifted in before them."""
    # a byte is a digit where its high half is 3 and its low half stays below 10 (adding 6 keeps
    # the high half 3); a carry out of a byte only comes from one that is not a digit
    other = ((w & _HIGH_HALVES) ^ _ZEROS) | (((w + _SIXES) & _HIGH_HALVES) ^ _ZEROS)
    k = np.int64(_trailing_zeros(other) >> _U3)
    if k == 0:
        return 0, _U0
    d = (w & _LOW_HALVES) << np.uint64(64 - 8 * k)
    d = d * _U10 + (d >> _U8)
    d = ((d & _SECOND_BYTES) * _TIMES_100 + ((d >> _U16) & _SECOND_BYTES) * _TIMES_1) >> _U32
    return k, d & _U64_MASK32


def _scan(data, n, out, corners, counts, starts, first, compare):
    """One pass over an OBJ file's bytes, data[:n]: (status, vertices (V, 3), corners, corner
    counts, face starts).

    Lines are split at \\n and \\r and fields at spaces and tabs, as the line-by-line parser
    splits plain ASCII (a leading UTF-8 byte order mark skipped, as it drops it); any other
    control character or a byte above 126 gives up (_CAREFUL). A line whose first field is ``v``
    must hold three plain decimal numbers (``[+-] digits [. digits] [(e|E) [+-] digits]`` with a
    digit in the mantissa, whose value Python's float gives finite; the rest of the line is
    ignored, as that parser ignores it), and one whose first field is ``f`` three or more corners
    (``[+-] digits``, optionally followed by ``/`` and anything; negative ones count back from
    the vertices so far), else it gives up. Vertices are written into `out`, and without
    `compare` the faces' corners and corner counts into `corners` and `counts`, and where each
    face's corners start in `data` (after its "f") into `starts` (-1 for a face with a relative
    corner): _FULL where one of them is full, and the caller gives larger ones. With `compare`,
    the vertices must fill `out` exactly and the faces be `corners` and `counts`, else it gives
    up; `first` is then the first frame's bytes and padding (its data[: n + _PAD]) and `starts`
    where its faces start: a face whose line holds the same bytes as the first frame's (up to
    its line end) has its corners, and is not read again. Nothing is allocated, so that no array
    changes in the loop (numba counts references to an array that does).

    Numbers: digits are read 8 at a time (:func:`_digit_run`) into an integer mantissa;
    Clinger's fast path rounds the easy ones (mantissa up to 2**53, exponent up to 22), Eisel
    and Lemire's conversion the others (17 digits, large exponents); a number of more than 19
    significant digits goes to :func:`_long_number`.

    Bounds: data[n : n + _PAD] must be line ends (checked first). Every loop over the bytes stops
    at a line end, so none passes index n; a line's first byte is looked at only below n, and
    the byte after it then at most at n; a word (:func:`_word`) is read from an index at most n.
    The last _PAD bytes of `first` must be line ends too (checked first), a start in it is used
    where it is at most len(first) - _PAD, and a word of it is read only 8 bytes after one that
    held no line end. Rows of `out`, `corners`, `counts` and `starts` are written or read after
    comparing the count with their length."""
    points = out
    if n < 0 or len(data) < n + _PAD or points.shape[1] != 3:
        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
    for k in range(n, n + _PAD):
        if data[k] != _LINE_END:
            return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
    if compare:
        if len(first) < _PAD:
            return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
        for k in range(len(first) - _PAD, len(first)):
            if first[k] != _LINE_END:
                return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
    count = 0
    n_corners, n_faces, largest = 0, 0, -1
    i = 3 if n >= 3 and data[0] == 0xEF and data[1] == 0xBB and data[2] == 0xBF else 0
    while i < n:
        c = _at(data, i)
        while c == 32 or c == 9:
            i += 1
            c = _at(data, i)
        if c == 10 or c == 13:
            i += 1
            continue
        after = _at(data, i + 1)  # i < n here: the line holds a byte other than a line end
        if c == 118 and (after == 32 or after == 9 or after == 10 or after == 13):  # "v"
            i += 1
            if count == len(points):
                return _CAREFUL if compare else _FULL, points[:0], corners[:0], counts[:0], starts[:0]
            for axis in range(3):
                c = _at(data, i)
                while c == 32 or c == 9:
                    i += 1
                    c = _at(data, i)
                start = i
                negative = c == 45
                if c == 43 or c == 45:
                    i += 1
                mantissa, begin = _U0, i
                while True:  # the integer's digits, 8 at a time
                    k, run = _digit_run(_word(data, i))
                    mantissa = mantissa * _RUN_POWERS[k] + run  # wraps past 19 digits, which go elsewhere
                    i += k
                    if k < 8:
                        break
                digits, scale = i - begin, 0
                if _at(data, i) == 46:  # the point, and the fraction's digits
                    i += 1
                    fraction = i
                    while True:
                        k, run = _digit_run(_word(data, i))
                        if k < 8:
                            mantissa = mantissa * _RUN_POWERS[k] + run
                            i += k
                            break
                        mantissa = mantissa * _TEN_TO_8 + run  # a step of 8: the next word is read before
                        i += 8  # these digits are added up
                    digits, scale = digits + i - fraction, fraction - i
                if digits == 0:
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                c = _at(data, i)
                if c == 101 or c == 69:  # "e" or "E"
                    i += 1
                    sign = 1
                    c = _at(data, i)
                    if c == 43 or c == 45:
                        sign = -1 if c == 45 else 1
                        i += 1
                    exponent, exponent_digits = 0, 0
                    c = _at(data, i)
                    while 48 <= c <= 57:
                        if exponent < 100_000:
                            exponent = exponent * 10 + (c - 48)
                        exponent_digits += 1
                        i += 1
                        c = _at(data, i)
                    if exponent_digits == 0:
                        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                    scale += sign * exponent
                if not (c == 32 or c == 9 or c == 10 or c == 13):  # more in the field: the careful parser judges it
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                if digits > _KEPT_DIGITS:  # leading zeros aside?
                    j = begin
                    while _at(data, j) == 48 or _at(data, j) == 46:
                        digits -= _at(data, j) == 48
                        j += 1
                if digits > _KEPT_DIGITS:
                    i, value, good = _long_number(data, start, n)
                    if not good:
                        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                    points[np.uint64(count), np.uint64(axis)] = value
                    continue
                if mantissa == 0:
                    value = 0.0
                elif mantissa <= _EXACT_MANTISSA and -22 <= scale <= 22:
                    value = float(mantissa) * _POWERS[scale] if scale >= 0 else float(mantissa) / _POWERS[-scale]
                else:
                    value = _eisel_lemire(mantissa, scale)
                    if value == np.inf:
                        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                points[np.uint64(count), np.uint64(axis)] = -value if negative else value
            count += 1
        elif c == 102 and (after == 32 or after == 9 or after == 10 or after == 13):  # "f"
            i += 1
            j = starts[np.uint64(n_faces)] if compare and n_faces < len(starts) and n_faces < len(counts) else -1
            if 0 <= j <= len(first) - _PAD:
                k = i
                while True:  # the line's bytes against the first frame's, 8 at a time
                    w = _word(data, k)
                    differ = np.int64(_trailing_zeros(w ^ _word(first, j)) >> _U3)  # the first byte that differs
                    end = np.int64(_trailing_zeros(_zero_bytes(w ^ _LINE_FEEDS) | _zero_bytes(w ^ _RETURNS)) >> _U3)
                    if end < differ or end < 8 or differ < 8:
                        break
                    k += 8
                    j += 8
                if end < differ:  # the same bytes up to the line end, which both have
                    i = k + end
                    n_corners += counts[np.uint64(n_faces)]
                    n_faces += 1
                    continue
            own, relative, begin_face = 0, False, i
            while True:
                c = _at(data, i)
                while c == 32 or c == 9:
                    i += 1
                    c = _at(data, i)
                if c == 10 or c == 13:
                    break
                negative = c == 45
                if c == 43 or c == 45:
                    i += 1
                index, begin = 0, i
                while True:  # at most 16 digits: a 17th is not a field's end below
                    k, run = _digit_run(_word(data, i))
                    index = index * np.int64(_RUN_POWERS[k]) + np.int64(run)
                    i += k
                    if k < 8 or i - begin >= 16:
                        break
                if index == 0 or index > _MAX_VERTEX:
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                if _at(data, i) == 47:  # "/" and texture or normal numbers, which are ignored
                    while 32 < _at(data, i) <= 126:
                        i += 1
                c = _at(data, i)
                if not (c == 32 or c == 9 or c == 10 or c == 13):
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                corner = count - index if negative else index - 1
                relative = relative or negative
                if corner < 0:
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                largest = max(largest, corner)
                if n_corners >= len(corners):
                    return _CAREFUL if compare else _FULL, points[:0], corners[:0], counts[:0], starts[:0]
                if compare:
                    if corners[np.uint64(n_corners)] != corner:
                        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
                else:
                    corners[np.uint64(n_corners)] = corner
                n_corners += 1
                own += 1
            if own < 3:
                return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
            if n_faces >= len(counts) or n_faces >= len(starts):
                return _CAREFUL if compare else _FULL, points[:0], corners[:0], counts[:0], starts[:0]
            if compare:
                if counts[np.uint64(n_faces)] != own:
                    return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
            else:
                counts[np.uint64(n_faces)] = own
                starts[np.uint64(n_faces)] = -1 if relative else begin_face
            n_faces += 1
        c = _at(data, i)
        while c != 10 and c != 13:  # the rest of the line: plain ASCII or tabs
            if c > 126 or (c < 32 and c != 9):
                return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
            i += 1
            c = _at(data, i)
    if count == 0 or largest >= count:
        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
    if compare and (count != len(points) or n_faces != len(counts) or n_corners != len(corners)):
        return _CAREFUL, points[:0], corners[:0], counts[:0], starts[:0]
    return _READ, points[:count], corners[:n_corners], counts[:n_faces], starts[:n_faces]


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
