"""Compiled loops that read a crowd's numpy store: each part's entries sampled, interpolated between
frames and blended in one pass (``read_entries``), and forward kinematics (``world_matrices``).

They compute what the array API path of ``flockkit.crowd.runtime`` computes (``interpolate_entries``
then ``blend_entries``), part by part, straight from the store into the caller's output, with no
temporaries the size of the output: the array API path makes about ten (gathers, differences,
weights, masks), so it moves several times the bytes a blend must move. Both run in float32, as the
store holds poses; the loops let the compiler reorder float32 sums and contract them into
multiply-adds (``fastmath``), so the two paths agree to float32 rounding, not bit for bit
(tests/core/test_crowd_kernels.py).

Reading between two frames slerps, as the array API path does, but with the angle and the sines
as polynomials (``_acos`` and ``_sin`` below, both within 2e-8 of the functions on the range they
are used on) instead of library calls: the trigonometry of 4 096 parts of 82 joints otherwise
costs more than reading their poses. The slerp's weights are scaled to give a unit quaternion, as
the array API path's are, so an error in them moves the result along the arc between the two
frames by that error times the arc (at most 2e-8 of a rotation between frames).

Parts are spread over numba's threads (``numba.set_num_threads``) in chunks of ``CHUNK``; each
part is written by one thread only, so the result does not depend on the number of threads.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import float32

# Parts per task of the parallel loops: a task's scratch (two poses) is made once per chunk.
CHUNK = 64
_FAST = {"cache": True, "nogil": True, "fastmath": True, "error_model": "numpy", "boundscheck": False}


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
def _sin(x):  # pragma: no cover - compiled
    """sin(x) for x in [0, pi / 2], within 1e-9 (its Taylor series to x^11)."""
    x2 = x * x
    s = float32(-1 / 39916800)
    s = s * x2 + float32(1 / 362880)
    s = s * x2 - float32(1 / 5040)
    s = s * x2 + float32(1 / 120)
    s = s * x2 - float32(1 / 6)
    return x * (s * x2 + float32(1))


@numba.njit(inline="always", **_FAST)
def _between(a, b, u, out):  # pragma: no cover - compiled
    """Entries `a` (J, 12) moved `u` of the way to `b`, into `out`: rotations slerped the shorter
    way round (linear weights where the two are within 1e-4 of one rotation), the rest lerped;
    ``interpolate_entries``'s formula."""
    for j in range(a.shape[0]):
        aj, bj, oj = a[j], b[j], out[j]
        dot = aj[0] * bj[0] + aj[1] * bj[1] + aj[2] * bj[2] + aj[3] * bj[3]
        sign = float32(1.0) if dot >= float32(0.0) else float32(-1.0)
        angle = _acos(min(dot * sign, float32(1.0)))
        sine = _sin(angle)
        if sine < float32(1e-4):
            wa, wb = float32(1.0) - u, u * sign
        else:
            wa, wb = _sin((float32(1.0) - u) * angle) / sine, _sin(u * angle) / sine * sign
        length = math.sqrt(wa * wa + wb * wb + float32(2.0) * wa * wb * dot)
        wa, wb = wa / length, wb / length
        for c in range(4):
            oj[c] = wa * aj[c] + wb * bj[c]
        for c in range(4, 12):
            oj[c] = aj[c] + u * (bj[c] - aj[c])


@numba.njit(inline="always", **_FAST)
def _blend(a, b, w, out):  # pragma: no cover - compiled
    """Entries `a` (J, 12) blended towards `b` by `w` in (0, 1), into `out` (may be `a`): rotations
    nlerped towards whichever of b and -b is nearer, the rest lerped; ``blend_entries``'s
    formula."""
    for j in range(a.shape[0]):
        aj, bj, oj = a[j], b[j], out[j]
        dot = aj[0] * bj[0] + aj[1] * bj[1] + aj[2] * bj[2] + aj[3] * bj[3]
        sign = float32(1.0) if dot >= float32(0.0) else float32(-1.0)
        x0 = aj[0] + w * (sign * bj[0] - aj[0])
        x1 = aj[1] + w * (sign * bj[1] - aj[1])
        x2 = aj[2] + w * (sign * bj[2] - aj[2])
        x3 = aj[3] + w * (sign * bj[3] - aj[3])
        inverse = float32(1.0) / math.sqrt(x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3)
        for c in range(4, 12):
            oj[c] = aj[c] + w * (bj[c] - aj[c])
        oj[0], oj[1], oj[2], oj[3] = x0 * inverse, x1 * inverse, x2 * inverse, x3 * inverse


@numba.njit(inline="always", **_FAST)
def _copy(a, out):  # pragma: no cover - compiled
    """out[:] = a, element by element: numba's slice assignment guards against overlap with a
    temporary copy (an allocation per part)."""
    for j in range(a.shape[0]):
        for c in range(12):
            out[j, c] = a[j, c]


@numba.njit(inline="always", **_FAST)
def _entry(store, unique, row, on_unique, width):  # pragma: no cover - compiled
    """The `width` floats at `row` of the store, or of the unique pool's store (flat)."""
    if on_unique:
        return unique[row : row + width]
    return store[row : row + width]


@numba.njit(parallel=True, **_FAST)
def read_entries(store, unique, rows, unique_rows, shares, alpha, places, out):  # pragma: no cover - compiled
    """Each part i's entries into out[places[i]] (J, 12): its source read between the entries at
    rows[i, 0] (newer) and rows[i, 1] (older) shares[i, 0] of the way, and, where alpha[i] > 0,
    blended by alpha[i] towards its target, read likewise at rows[i, 2:4] and shares[i, 1].

    Rows are float offsets into `store` (flat), or into `unique` (flat) where unique_rows[i, 0]
    (source) or unique_rows[i, 1] (target) is set. A share of 0 reads the newer entry alone; an
    alpha of 0 or less the source alone, 1 or more the target alone, exactly."""
    n, bones = len(places), out.shape[1]
    width = bones * 12
    for chunk in numba.prange((n + CHUNK - 1) // CHUNK):
        target = np.empty((bones, 12), dtype=np.float32)
        for i in range(chunk * CHUNK, min(n, (chunk + 1) * CHUNK)):
            o = out[places[i]]
            a = _entry(store, unique, rows[i, 0], unique_rows[i, 0], width).reshape(bones, 12)
            if shares[i, 0] > 0:
                older = _entry(store, unique, rows[i, 1], unique_rows[i, 0], width).reshape(bones, 12)
                _between(a, older, shares[i, 0], o)
            else:
                _copy(a, o)
            w = alpha[i]
            if w <= 0:
                continue
            b = _entry(store, unique, rows[i, 2], unique_rows[i, 1], width).reshape(bones, 12)
            if shares[i, 1] > 0:
                older = _entry(store, unique, rows[i, 3], unique_rows[i, 1], width).reshape(bones, 12)
                _between(b, older, shares[i, 1], target)
                b = target
            if w >= 1:
                _copy(b, o)
            else:
                _blend(o, b, w, o)


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
