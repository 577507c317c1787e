"""Compiled loops of the annotated walk (annotated.py) on graphs that do not turn.

Each loop does what its Python counterpart in annotated._Problem does, step for step and in the
same floating-point operations, so that walks are the same edge for edge: sums over output
frames are numpy's pairwise sums (``_pairwise``, as ``ndarray.sum`` adds float64 along a
contiguous axis), products and sums keep the Python code's order, and random numbers are drawn
by the caller, in the order the Python pass draws them, and handed in.

The frame error of source frame f at output frame t is the norm of ``features[f] - track[t]``
(the source arrow against the target), plus ``in_step`` where ``step[f, t]`` (in step with an
avoided walk; ``step`` has no rows without walks to avoid).
"""

from __future__ import annotations

import numba
import numpy as np

# `since` (clip frames since the last transition) before any transition: larger than any blend
NEVER = 1 << 50


@numba.njit(cache=True, nogil=True)
def _pairwise(a, n):
    """a[:n].sum() as numpy adds float64: blocks of up to 128 in 8 partial sums, halves (cut at
    a multiple of 8) added pairwise; the halving done with a stack instead of recursion."""
    if n <= 128:
        return _block(a, 0, n)
    lo, size, stage = np.empty(64, dtype=np.int64), np.empty(64, dtype=np.int64), np.empty(64, dtype=np.int64)
    values = np.empty(64)
    lo[0], size[0], stage[0] = 0, n, 0
    top, stored = 0, 0
    while top >= 0:
        m = size[top]
        if m <= 128:
            values[stored] = _block(a, lo[top], m)
            stored += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stage[top] == 0:  # the first half
            stage[top] = 1
            lo[top + 1], size[top + 1], stage[top + 1] = lo[top], half, 0
            top += 1
        elif stage[top] == 1:  # then the second
            stage[top] = 2
            lo[top + 1], size[top + 1], stage[top + 1] = lo[top] + half, m - half, 0
            top += 1
        else:  # both done: their sum
            stored -= 1
            values[stored - 1] = values[stored - 1] + values[stored]
            top -= 1
    return values[0]


@numba.njit(cache=True, nogil=True)
def _block(a, lo, n):
    """numpy's pairwise sum of a[lo:lo + n] for n <= 128."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    whole = n - n % 8
    while i < whole:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True, nogil=True, inline="always")
def _error(features, track, step, in_step, frame, t, react):
    """frame_error of source `frame` at output frame t (in step counted while react > 0): the
    norm of the arrows' difference as numpy.linalg.norm makes it (squares added in order)."""
    total = 0.0
    for d in range(features.shape[1]):
        x = features[frame, d] - track[t, d]
        total += x * x
    error = np.sqrt(total)
    if react > 0 and step.shape[0] > 0 and step[frame, t]:
        error += in_step
    return error


@numba.njit(cache=True, nogil=True)
def initial(
    state,
    shifted,
    uniforms,
    out_kind,
    out_index,
    edge_kind,
    edge_index,
    edge_ahead,
    edge_fixed,
    n_edges,
    clip_frames,
    clip_target,
    trans_target,
    shift,
    straight,
    features,
    track,
    step,
    ints,
    floats,
):
    """_Problem.initial's loop (past the start) on tables. `state` (node, output frame, since,
    drift so far, uniforms used, edges made) and `shifted` (phase shifts taken) are updated in
    place, and the edges made written to out_kind (0 clip, 1 transition) and out_index. Each
    node's edges are laid out as _Shared.choices lists them, padded: kind (-1 padding), index,
    the node each looks ahead from and its fixed cost. `ints`: needed, longest, clips, drift,
    look-ahead frames, react (-1: all of them), whether walks are avoided; `floats`: alpha, dt,
    noise, vary, in_step. Returns 0 when the walk covers its frames, 1 when it needs more
    uniforms or room for edges (call again with more: nothing of the step was done), 2 when the
    node in state has no edge to take."""
    needed, longest, n_clips, drift = ints[0], ints[1], ints[2], ints[3]
    ahead, react, avoiding = ints[4], ints[5], ints[6]
    alpha, dt, noise, vary, in_step = floats[0], floats[1], floats[2], floats[3], floats[4]
    width = edge_kind.shape[1]
    keep = np.empty(width, dtype=np.int64)
    error = np.empty(ahead)
    while state[1] < needed:
        node, t, since, drifted, used, made = state[0], state[1], state[2], state[3], state[4], state[5]
        kept = 0
        if since < longest:  # the clip alone until the last blend has played out
            if node < n_clips:
                keep[0] = 0
                kept = 1
        else:  # phase shifts only while they keep the timing within `drift` frames of the start's
            for k in range(n_edges[node]):
                if edge_kind[node, k] == 0 or abs(drifted + shift[edge_index[node, k]]) <= drift:
                    keep[kept] = k
                    kept += 1
        if kept == 0:
            return 2
        draws = 1 if kept == 1 else kept
        if used + draws > len(uniforms) or made >= len(out_kind):
            return 1
        if kept == 1:
            chosen = keep[0]
        else:
            m = min(ahead, needed - t)
            limit = m if react < 0 else min(react, m)
            any_shift = False
            any_fresh = False
            for q in range(kept):
                k = keep[q]
                if edge_kind[node, k] == 1 and shift[edge_index[node, k]] != 0:
                    any_shift = True
                    if not shifted[edge_index[node, k]]:
                        any_fresh = True
            best, best_value = 0, np.inf
            for q in range(kept):
                k = keep[q]
                row = edge_ahead[node, k]
                for c in range(m):
                    error[c] = _error(features, track, step, in_step, straight[row, c], t + c,
                                      avoiding * (c < limit))  # fmt: skip
                value = alpha * (_pairwise(error, m) * dt) + edge_fixed[node, k]
                if any_shift:
                    is_shift = edge_kind[node, k] == 1 and shift[edge_index[node, k]] != 0
                    taken = edge_kind[node, k] == 1 and shifted[edge_index[node, k]]
                    if taken or (not is_shift and any_fresh):
                        value = value + vary
                    else:
                        value = value + 0.0
                value = value + noise * uniforms[used + q]
                if value < best_value:
                    best, best_value = q, value
            chosen = keep[best]
            index = edge_index[node, chosen]
            if edge_kind[node, chosen] == 1 and shift[index] != 0:
                shifted[index] = True
                state[3] = drifted + shift[index]
        kind, index = edge_kind[node, chosen], edge_index[node, chosen]
        out_kind[made], out_index[made] = kind, index
        state[4], state[5] = used + draws, made + 1
        if kind == 0:
            state[0], state[1], state[2] = clip_target[index], t + clip_frames[index], since + clip_frames[index]
        else:
            state[0], state[2] = trans_target[index], 0
    return 0


@numba.njit(cache=True, nogil=True)
def replace(old_kind, old_index, suffix, out, out_count, trans_target, trans_cost, shift, clip_frames, clip_target,
            nodes, features, track, step, ints, floats, best_kind, best_index):  # fmt: skip
    """_Problem.replace's search on tables: the best alternative to the old edges (old_kind,
    old_index: 0 clip, 1 transition) written to best_kind and best_index; returns how many
    edges it has, -1 when none lowers E. `suffix`: the source frames the path plays after the
    stretch (empty for a stretch at the tail); `out`, `out_count`: each node's transitions.
    `ints`: start node, since, t0, old frames, tail, goal, slack, lead (-1: none), needed,
    longest, most transitions, most nodes expanded, clips, period (0: none), avoiding; `floats`:
    the cost to beat, alpha, dt, beta, in_step."""
    start, since0, t0, old_frames = ints[0], ints[1], ints[2], ints[3]
    tail, goal, slack, lead = ints[4] > 0, ints[5], ints[6], ints[7]
    needed, longest, max_trans, search_nodes = ints[8], ints[9], ints[10], ints[11]
    n_clips, period, avoiding = ints[12], ints[13], ints[14]
    best_cost, alpha, dt, beta, in_step = floats[0], floats[1], floats[2], floats[3], floats[4]
    size = 1 + search_nodes * (out.shape[1] + 1)
    # the stack, and every edge list as a chain of (parent, kind, index) entries
    s_node = np.empty(size, dtype=np.int64)
    s_since = np.empty(size, dtype=np.int64)
    s_frames = np.empty(size, dtype=np.int64)
    s_list = np.empty(size, dtype=np.int64)
    s_trans = np.empty(size, dtype=np.int64)
    s_cost = np.empty(size)
    parent = np.empty(size + 1, dtype=np.int64)
    e_kind = np.empty(size + 1, dtype=np.int64)
    e_index = np.empty(size + 1, dtype=np.int64)
    length = np.empty(size + 1, dtype=np.int64)
    parent[0], length[0] = -1, 0  # entry 0: no edges
    lists = 1
    longest_clip = 0
    for k in range(len(clip_frames)):
        longest_clip = max(longest_clip, clip_frames[k])
    error = np.empty(max(longest_clip, len(suffix), 1))
    # the rest's cost by the frames the replacement plays (within slack of the old: done ends there)
    low = old_frames - slack
    rests = np.full(2 * slack + 1, np.nan)
    s_node[0], s_since[0], s_frames[0], s_list[0], s_trans[0], s_cost[0] = start, since0, 0, 0, 0, 0.0
    top = 1
    expanded = 0
    best = -1
    n_old = len(old_kind)
    while top > 0 and expanded < search_nodes:
        top -= 1
        node, since, frames, own, n_trans, cost = (
            s_node[top],
            s_since[top],
            s_frames[top],
            s_list[top],
            s_trans[top],
            s_cost[top],
        )
        expanded += 1
        if tail:
            done = frames >= needed - t0
        else:
            done = node == goal and abs(frames - old_frames) <= slack
        if done and (tail or lead < 0 or since + lead >= longest):
            same = length[own] == n_old
            if same:
                at = own
                for q in range(n_old - 1, -1, -1):
                    if e_kind[at] != old_kind[q] or e_index[at] != old_index[q]:
                        same = False
                        break
                    at = parent[at]
            # the rest's cost is never negative: a replacement whose own cost already reaches the
            # cost to beat cannot beat it, and its rest need not be made (the same best either way)
            if not same:
                if cost < best_cost:
                    rest = 0.0
                    if not tail:
                        t = t0 + frames
                        if t + len(suffix) - 1 < needed:
                            rest = np.inf
                        elif rests[frames - low] == rests[frames - low]:  # made before: not NaN
                            rest = rests[frames - low]
                        else:
                            n = max(needed - t, 0)
                            for c in range(n):
                                error[c] = _error(features, track, step, in_step, suffix[c], t + c, avoiding)
                            rest = alpha * dt * _pairwise(error, n)
                            rests[frames - low] = rest
                    total = cost + rest
                    if total < best_cost:
                        best, best_cost = own, total
                if tail:
                    continue
        if frames > old_frames + slack:
            continue
        if since >= longest and n_trans < max_trans:
            for q in range(out_count[node]):
                index = out[node, q]
                extra = trans_cost[index] + (0.0 if shift[index] != 0 else beta)
                parent[lists], e_kind[lists], e_index[lists], length[lists] = own, 1, index, length[own] + 1
                s_node[top], s_since[top], s_frames[top], s_list[top] = trans_target[index], 0, frames, lists
                s_trans[top], s_cost[top] = n_trans + 1, cost + extra
                lists += 1
                top += 1
        if node < n_clips:
            n = clip_frames[node]
            t = t0 + frames
            m = max(min(n, needed - t), 0)
            for c in range(m):
                frame = nodes[node] + c
                if period > 0:
                    frame %= period
                error[c] = _error(features, track, step, in_step, frame, t + c, avoiding)
            parent[lists], e_kind[lists], e_index[lists], length[lists] = own, 0, node, length[own] + 1
            s_node[top], s_since[top], s_frames[top], s_list[top] = clip_target[node], since + n, frames + n, lists
            s_trans[top], s_cost[top] = n_trans, cost + alpha * dt * _pairwise(error, m)
            lists += 1
            top += 1
    if best < 0:
        return -1
    count = length[best]
    at = best
    for q in range(count - 1, -1, -1):
        best_kind[q], best_index[q] = e_kind[at], e_index[at]
        at = parent[at]
    return count
