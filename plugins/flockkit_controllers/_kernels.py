"""The compiled loop that writes many clip players' poses into a crowd's store at once.

Each pose is computed as ``SkeletalClip.sample`` computes a frames clip's (flockkit.skeleton's
LINEAR keys): rotations ``sin((1 - u) a) / sin(a) q_k + sin(u a) / sin(a) q'_k+1`` (q' the next
key turned to the near side), translations ``(1 - u) t_k + u t_k+1``, in float64 and in the same
order of operations, then rounded to float32 as the store holds it; so a batched stream's poses
equal its controller's ``pose`` rounded to float32. The clips' keys are read where the clips
hold them (no copy); each interval's angle a and sin(a), signed by the side the next key is
turned to, come from a table worked out once.
"""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, nogil=True)
def write_frames(
    rows, clips, keys, intervals, shares, rotations, translations, angles, sines, out, stride
):  # pragma: no cover
    """For each i: clip clips[i]'s pose between its keys keys[i] and keys[i] + 1 (table row
    intervals[i]) at share shares[i] of the way, joint j written at out[rows[i] + stride * j]
    (rotation 4 floats, translation 3)."""
    for i in range(len(rows)):
        q, t = rotations[clips[i]], translations[clips[i]]
        k, r, u, base = keys[i], intervals[i], shares[i], rows[i]
        following = min(k + 1, q.shape[0] - 1)  # a clip of one frame holds it (u is 0)
        for j in range(q.shape[1]):
            angle, signed = angles[r, j], sines[r, j]
            sine = abs(signed)
            side = 1.0 if signed > 0 else -1.0
            wa = math.sin((1 - u) * angle) / sine
            wb = math.sin(u * angle) / sine
            at = base + stride * j
            for c in range(4):
                out[at + c] = wa * q[k, j, c] + wb * (side * q[following, j, c])
            for c in range(3):
                out[at + 4 + c] = (1 - u) * t[k, j, c] + u * t[following, j, c]
