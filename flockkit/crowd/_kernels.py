"""Compiled loops that read a crowd's numpy store: where each part reads, found from its instance
record and its streams' rings (``plan_reads``), each part's entries sampled, interpolated between
frames and blended in one pass (``read_entries``), and forward kinematics (``world_matrices``).

They compute what the array API path of ``flockkit.crowd.runtime`` computes (``interpolate_entries``
then ``blend_entries``), part by part, straight from the store into the caller's output, with no
temporaries the size of the output: the array API path makes about ten (gathers, differences,
weights, masks), so it moves several times the bytes a blend must move. Both run in float32, as the
store holds poses; the loops let the compiler reorder float32 sums and contract them into
multiply-adds (``fastmath``: the inputs are finite, as the store checks its poses), so the two
paths agree to float32 rounding, not bit for bit (tests/core/test_crowd_kernels.py).

A store entry interleaves each joint's 12 floats (rotation, translation, scale), which keeps the
compiler from running the rotation arithmetic over many joints at once. So a part is read in
stages over its joints: the rotations of the entries it reads are first moved into compact
scratch rows (4 floats a joint, each moved as one 16-byte value through a ``complex128`` view:
bits copied, no arithmetic), slerped and blended there with every joint's arithmetic free of
branches (the compiler runs it 16 joints to an AVX-512 register), and written over the rotations
of an output entry whose translations and scales were lerped in one contiguous pass. The next
part's source entry is prefetched while one part is computed (parts read scattered entries).

Reading between two frames slerps, as the array API path does, but with the angle as a
polynomial (``_acos``, within 2e-8 of acos on [0, 1]) and the slerp's weights sin(t angle) /
sin(angle) as t sinc(t angle) with sinc a polynomial (``_sinc``, within 6e-8 relative on
[0, pi / 2]) instead of library calls: the trigonometry of 4 096 parts of 82 joints otherwise costs
more than reading their poses. The weights are scaled to give a unit quaternion, as the array API
path's are (which also cancels the common factor angle / sin(angle)), so an error in them moves
the result along the arc between the two frames, not off it: in exact arithmetic by at most 3e-9 of
the arc (measured over angles 0 to a half turn and every share), so float32 rounding is what is
left. Weights of nearly equal frames need no special case: sinc(0) is 1.

Parts are spread over numba's threads (``numba.set_num_threads``) in chunks of ``CHUNK``, handed
out one at a time (a thread that the machine's other work holds up leaves the rest of the chunks
to the others); each part is written by one thread only, so the result does not depend on the
number of threads.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba import float32, types
from numba.core import cgutils
from numba.extending import intrinsic

# Parts per task of the parallel loops: a task's scratch (four rows of rotations) is made once
# per chunk; chunks are small so that threads share the work evenly when one is held up.
CHUNK = 16
# Parts per task of ``plan_reads`` (a few dozen nanoseconds a part).
PLAN_BLOCK = 512
_FAST = {"cache": True, "nogil": True, "fastmath": True, "error_model": "numpy", "boundscheck": False}
# Loops whose arithmetic must round as numpy's does (no reordering, no reciprocals).
_EXACT = {**_FAST, "fastmath": False}


@intrinsic
def _prefetch(typingctx, array, index):  # pragma: no cover - compiled
    """Ask the caches for the line holding array[index] (a hint: no load, no fault)."""

    def codegen(context, builder, signature, args):
        kind = signature.args[0]
        pointer = cgutils.get_item_pointer(
            context, builder, kind, context.make_array(kind)(context, builder, args[0]), [args[1]], wraparound=False
        )
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [pointer.type, i32, i32, i32]), "llvm.prefetch.p0"
        )
        builder.call(function, [pointer, i32(0), i32(3), i32(1)])  # read, keep in every level, data
        return context.get_dummy_value()

    return types.void(array, index), codegen


@numba.njit(inline="always", **_FAST)
def _fetch(flat, row, width):  # pragma: no cover - compiled
    """Prefetch the `width` floats at `row` of `flat`, a 64-byte line at a time."""
    for k in range(0, width, 16):
        _prefetch(flat, row + k)


@numba.njit(inline="always", **_FAST)
def _acos(x):  # pragma: no cover - compiled
    """acos(x) for x in [0, 1], within 2e-8 (Abramowitz and Stegun 4.4.46)."""
    p = float32(-0.0012624911)
    p = p * x + float32(0.0066700901)
    p = p * x - float32(0.0170881256)
    p = p * x + float32(0.0308918810)
    p = p * x - float32(0.0501743046)
    p = p * x + float32(0.0889789874)
    p = p * x - float32(0.2145988016)
    p = p * x + float32(1.5707963050)
    return math.sqrt(max(float32(1.0) - x, float32(0.0))) * p


@numba.njit(inline="always", **_FAST)
def _sinc(x):  # pragma: no cover - compiled
    """sin(x) / x for x in [0, pi / 2], within 6e-8 relative (its Taylor series to x^10)."""
    x2 = x * x
    s = float32(-1 / 39916800)
    s = s * x2 + float32(1 / 362880)
    s = s * x2 - float32(1 / 5040)
    s = s * x2 + float32(1 / 120)
    s = s * x2 - float32(1 / 6)
    return s * x2 + float32(1)


@numba.njit(inline="always", **_FAST)
def _rotations(wide, row, q, bones):  # pragma: no cover - compiled
    """The rotations of the entry at float offset `row` of a store seen as 16-byte values
    (`wide`), into q (bones,) complex128: 4 floats a joint, contiguous."""
    first = row // 4
    for j in range(bones):
        q[j] = wide[first + 3 * j]


@numba.njit(inline="always", **_FAST)
def _put_rotations(q, wide, row, bones):  # pragma: no cover - compiled
    """Compact rotations q over those of the entry at float offset `row` of `wide`."""
    first = row // 4
    for j in range(bones):
        wide[first + 3 * j] = q[j]


@numba.njit(inline="always", **_FAST)
def _slerp(p, q, u, out, bones):  # pragma: no cover - compiled
    """Compact rotations (bones * 4 floats) `p` moved `u` of the way to `q`, into `out` (may be
    `p`): slerped the shorter way round; ``interpolate_entries``'s rotations."""
    one = float32(1.0)
    v = one - u
    for j in range(bones):
        k = 4 * j
        p0, p1, p2, p3 = p[k], p[k + 1], p[k + 2], p[k + 3]
        q0, q1, q2, q3 = q[k], q[k + 1], q[k + 2], q[k + 3]
        dot = p0 * q0 + p1 * q1 + p2 * q2 + p3 * q3
        sign = one if dot >= 0 else -one  # -q is q's rotation, nearer
        x = min(dot * sign, one)
        angle = _acos(x)
        wp = v * _sinc(v * angle)  # sin(v angle) / angle: the slerp's weights times sin(angle) / angle
        wq = u * _sinc(u * angle)
        scale = one / math.sqrt(wp * wp + wq * wq + float32(2.0) * wp * wq * x)  # |wp p + wq q| from the weights
        wp, wq = wp * scale, wq * scale * sign
        out[k], out[k + 1] = wp * p0 + wq * q0, wp * p1 + wq * q1
        out[k + 2], out[k + 3] = wp * p2 + wq * q2, wp * p3 + wq * q3


@numba.njit(inline="always", **_FAST)
def _nlerp(p, q, w, out, bones):  # pragma: no cover - compiled
    """Compact rotations `p` blended towards `q` by `w` in (0, 1), into `out` (may be `p`):
    nlerped towards whichever of q and -q is nearer; ``blend_entries``'s rotations."""
    one = float32(1.0)
    m = one - w
    for j in range(bones):
        k = 4 * j
        p0, p1, p2, p3 = p[k], p[k + 1], p[k + 2], p[k + 3]
        q0, q1, q2, q3 = q[k], q[k + 1], q[k + 2], q[k + 3]
        s = w if p0 * q0 + p1 * q1 + p2 * q2 + p3 * q3 >= 0 else -w
        x0, x1, x2, x3 = m * p0 + s * q0, m * p1 + s * q1, m * p2 + s * q2, m * p3 + s * q3
        scale = one / math.sqrt(x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3)
        out[k], out[k + 1], out[k + 2], out[k + 3] = x0 * scale, x1 * scale, x2 * scale, x3 * scale


@numba.njit(inline="always", **_FAST)
def _lerp2(a, b, ka, kb, out):  # pragma: no cover - compiled
    """out = ka a + kb b, float by float (translations and scales; the rotations are written
    over afterwards)."""
    for k in range(len(out)):
        out[k] = ka * a[k] + kb * b[k]


@numba.njit(inline="always", **_FAST)
def _lerp3(a, b, c, ka, kb, kc, out):  # pragma: no cover - compiled
    for k in range(len(out)):
        out[k] = ka * a[k] + kb * b[k] + kc * c[k]


@numba.njit(inline="always", **_FAST)
def _lerp4(a, b, c, d, ka, kb, kc, kd, out):  # pragma: no cover - compiled
    for k in range(len(out)):
        out[k] = ka * a[k] + kb * b[k] + kc * c[k] + kd * d[k]


@numba.njit(inline="always", **_FAST)
def _copy(a, out):  # pragma: no cover - compiled
    """out[:] = a, element by element: numba's slice assignment guards against overlap with a
    temporary copy (an allocation per part)."""
    for k in range(len(out)):
        out[k] = a[k]


@numba.njit(inline="always", **_FAST)
def _read(wide, newer, older, share, scratch, q, bones):  # pragma: no cover - compiled
    """Compact rotations (into q) of the entry read `share` of the way from float offset `newer`
    to `older` of `wide` (the newer alone where `share` is 0); `scratch` is overwritten."""
    _rotations(wide, newer, q, bones)
    if share > 0:
        _rotations(wide, older, scratch, bones)
        _slerp(q.view(np.float32), scratch.view(np.float32), share, q.view(np.float32), bones)


@numba.njit(parallel=True, **_EXACT)
def plan_reads(
    parts, ids, head, history, lookup, filled, unique_width, lag, then, rows, shares, unique_rows, alpha
):  # pragma: no cover - compiled
    """What ``read_entries`` reads for each part: part i is ``parts[ids[i]]`` (one cluster's column
    of a crowd's instance records: kind, stream, offset, target_kind, target, target_offset,
    blend_start, blend_time) as it was `lag` frames ago (offsets `lag` frames older, up to the
    oldest frame its stream holds), at crowd time `then` (float32, as the records' times are).
    Fills rows, shares, unique_rows and alpha (-1: not blending) as ``read_entries`` takes them,
    over numba's threads. Returns the first i whose part has no pose to read (kind NONE), or -1."""
    n = len(ids)
    first = n
    for block in numba.prange((n + PLAN_BLOCK - 1) // PLAN_BLOCK):
        for i in range(block * PLAN_BLOCK, min(n, (block + 1) * PLAN_BLOCK)):
            part = parts[ids[i]]
            if part.kind == 0:
                first = min(first, i)
                continue
            _plan_side(part.kind, part.stream, part.offset, head, history, lookup, filled, unique_width, lag,
                       rows, shares, unique_rows, i, 0)  # fmt: skip
            if part.blend_time > 0:
                _plan_side(part.target_kind, part.target, part.target_offset, head, history, lookup, filled,
                           unique_width, lag, rows, shares, unique_rows, i, 1)  # fmt: skip
                alpha[i] = min(max((then - part.blend_start) / part.blend_time, float32(0.0)), float32(1.0))
            else:
                rows[i, 2], rows[i, 3] = rows[i, 0], rows[i, 1]
                shares[i, 1], unique_rows[i, 1] = float32(0.0), False
                alpha[i] = float32(-1.0)
    return first if first < n else -1


@numba.njit(inline="always", **_EXACT)
def _plan_side(
    kind, index, offset, head, history, lookup, filled, unique_width, lag, rows, shares, unique_rows, i, side
):  # pragma: no cover - compiled
    """``plan_reads`` of one side (0: source, 1: target) of part i: a streamed side reads the
    store rows of the frames either side of its offset (the stream's ring slots
    ``(head - frame) % history``), a unique side its slot's row (index * unique_width), whole."""
    if kind == 2:
        rows[i, 2 * side] = rows[i, 2 * side + 1] = np.int64(index) * unique_width
        shares[i, side], unique_rows[i, side] = float32(0.0), True
        return
    stream, behind = (np.int64(index), np.float64(offset)) if kind == 1 else (np.int64(0), 0.0)
    if lag and kind == 1:  # the offset `lag` frames older (a float32 sum, as the records hold offsets)
        behind = min(np.float64(float32(offset + lag)), np.float64(filled[stream] - 1))
    whole = math.floor(behind)
    share = float32(behind - whole)
    slot = _ring(head[stream] - np.int64(whole), history[stream])
    newer = lookup[stream, slot]
    rows[i, 2 * side] = newer
    rows[i, 2 * side + 1] = lookup[stream, _ring(slot - 1, history[stream])] if share > 0 else newer
    shares[i, side], unique_rows[i, side] = share, False


@numba.njit(inline="always", **_EXACT)
def _ring(slot, history):  # pragma: no cover - compiled
    """slot % history (a ring buffer's slot), without the division where slot is already in
    0 .. history - 1 or one turn below: an integer division costs more than the rest of a part's plan."""
    if slot < 0:
        slot += history
    return slot if 0 <= slot < history else slot % history


def read_entries(store, unique, rows, unique_rows, shares, alpha, places, out) -> None:
    """Each part i's entries into out[places[i]] (J, 12): its source read between the entries at
    rows[i, 0] (newer) and rows[i, 1] (older) shares[i, 0] of the way, and, where alpha[i] > 0,
    blended by alpha[i] towards its target, read likewise at rows[i, 2:4] and shares[i, 1].

    Rows are float offsets into `store` (flat), or into `unique` (flat) where unique_rows[i, 0]
    (source) or unique_rows[i, 1] (target) is set. A share of 0 reads the newer entry alone; an
    alpha of 0 or less the source alone, 1 or more the target alone, exactly. `store`, `unique`
    and `out` hold a multiple of 4 floats (whole entries of 12)."""
    chunksize = numba.set_parallel_chunksize(1)  # this thread's parallel loops: chunks one at a time
    try:
        _read_chunks(store, unique, rows, unique_rows, shares, alpha, places, out)
    finally:
        numba.set_parallel_chunksize(chunksize)


@numba.njit(parallel=True, **_FAST)
def _read_chunks(store, unique, rows, unique_rows, shares, alpha, places, out):  # pragma: no cover - compiled
    """``read_entries`` over numba's threads, CHUNK parts a task."""
    n = len(places)
    for chunk in numba.prange((n + CHUNK - 1) // CHUNK):
        begin, end = chunk * CHUNK, min(n, (chunk + 1) * CHUNK)
        _read_parts(store, unique, rows, unique_rows, shares, alpha, places, out, begin, end)


@numba.njit(inline="always", **_FAST)
def _read_parts(store, unique, rows, unique_rows, shares, alpha, places, out, begin, end):  # pragma: no cover
    """``read_entries`` of parts begin..end - 1, in this thread."""
    bones = out.shape[1]
    width = bones * 12
    flat = out.reshape(-1)
    wide_out, wide_store, wide_unique = flat.view(np.complex128), store.view(np.complex128), unique.view(np.complex128)
    one = float32(1.0)
    scratch = np.empty(bones, np.complex128)
    source, target = np.empty(bones, np.complex128), np.empty(bones, np.complex128)
    for i in range(begin, end):
        if i + 1 < end:  # the next source, scattered in the store, on its way while this part runs
            _fetch(unique if unique_rows[i + 1, 0] else store, rows[i + 1, 0], width)
        o = flat[places[i] * width : (places[i] + 1) * width]
        src, wsrc = (unique, wide_unique) if unique_rows[i, 0] else (store, wide_store)
        tgt, wtgt = (unique, wide_unique) if unique_rows[i, 1] else (store, wide_store)
        ua, ub, w = shares[i, 0], shares[i, 1], alpha[i]
        if w <= 0 or w >= 1:  # one side alone: copied, or read between its two frames
            side, flats, wide = (0, src, wsrc) if w <= 0 else (2, tgt, wtgt)
            share = ua if w <= 0 else ub
            newer = flats[rows[i, side] : rows[i, side] + width]
            if share <= 0:
                _copy(newer, o)
            else:
                _read(wide, rows[i, side], rows[i, side + 1], share, scratch, source, bones)
                _lerp2(newer, flats[rows[i, side + 1] : rows[i, side + 1] + width], one - share, share, o)
                _put_rotations(source, wide_out, places[i] * width, bones)
            continue
        a, older_a = src[rows[i, 0] : rows[i, 0] + width], src[rows[i, 1] : rows[i, 1] + width]
        b, older_b = tgt[rows[i, 2] : rows[i, 2] + width], tgt[rows[i, 3] : rows[i, 3] + width]
        _read(wsrc, rows[i, 0], rows[i, 1], ua, scratch, source, bones)
        _read(wtgt, rows[i, 2], rows[i, 3], ub, scratch, target, bones)
        _nlerp(source.view(np.float32), target.view(np.float32), w, source.view(np.float32), bones)
        m = one - w
        if ua > 0:
            _lerp4(a, older_a, b, older_b, m * (one - ua), m * ua, w * (one - ub), w * ub, o)
        else:
            _lerp3(a, b, older_b, m, w * (one - ub), w * ub, o)
        _put_rotations(source, wide_out, places[i] * width, bones)


@numba.njit(parallel=True, **_FAST)
def world_matrices(entries, parents, scales, out):  # pragma: no cover - compiled
    """Forward kinematics: out[i, j] (4 x 4) = out[i, parents[j]] @ T R S of entries[i, j]
    (rotation x, y, z, w; translation), scaled by scales[j]; parents come before their children
    (a Skeleton's order). ``Skeleton.world``'s product, in float32."""
    n, bones = entries.shape[0], entries.shape[1]
    one, two = float32(1.0), float32(2.0)
    for i in numba.prange(n):
        e, m = entries[i], out[i]
        for j in range(bones):
            x, y, z, w = e[j, 0], e[j, 1], e[j, 2], e[j, 3]
            sx, sy, sz = scales[j, 0], scales[j, 1], scales[j, 2]
            l00, l01, l02 = (one - two * (y * y + z * z)) * sx, two * (x * y - z * w) * sy, two * (x * z + y * w) * sz
            l10, l11, l12 = two * (x * y + z * w) * sx, (one - two * (x * x + z * z)) * sy, two * (y * z - x * w) * sz
            l20, l21, l22 = two * (x * z - y * w) * sx, two * (y * z + x * w) * sy, (one - two * (x * x + y * y)) * sz
            tx, ty, tz = e[j, 4], e[j, 5], e[j, 6]
            mj, p = m[j], parents[j]
            if p < 0:
                mj[0, 0], mj[0, 1], mj[0, 2], mj[0, 3] = l00, l01, l02, tx
                mj[1, 0], mj[1, 1], mj[1, 2], mj[1, 3] = l10, l11, l12, ty
                mj[2, 0], mj[2, 1], mj[2, 2], mj[2, 3] = l20, l21, l22, tz
            else:
                mp = m[p]
                for r in range(3):
                    a0, a1, a2, a3 = mp[r, 0], mp[r, 1], mp[r, 2], mp[r, 3]
                    mj[r, 0] = a0 * l00 + a1 * l10 + a2 * l20
                    mj[r, 1] = a0 * l01 + a1 * l11 + a2 * l21
                    mj[r, 2] = a0 * l02 + a1 * l12 + a2 * l22
                    mj[r, 3] = a0 * tx + a1 * ty + a2 * tz + a3
            mj[3, 0], mj[3, 1], mj[3, 2], mj[3, 3] = float32(0.0), float32(0.0), float32(0.0), one
