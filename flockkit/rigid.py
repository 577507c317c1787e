"""Rigid motions in 2D and 3D, batched: the one place flockkit composes, inverts, applies and fits them.

A rigid motion is a pair (rotation R, translation t) acting on a point p as ``R p + t``; for the
row vectors flockkit stores that is ``p @ R.T + t``. Rotations are proper (det = +1). Every
function broadcasts over leading axes: rotations (..., D, D), translations (..., D), points
(..., D). To move the N agents of F frames by one motion per frame, pass ``rotations[:, None]``
against points (F, N, D).

Products are written out component by component rather than as batched matrix products, so that
a result does not depend on the batch it was computed in (a metric gives bit-identical distances
for a pair alone or among thousands).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "apply",
    "rotate",
    "compose",
    "invert",
    "chain",
    "kabsch",
    "turn",
    "rotation",
    "quaternion_product",
    "quaternion_matrix",
    "trs",
    "slerp",
    "nlerp",
    "facing",
]


def rotate(rotation, vectors) -> np.ndarray:
    """``R v`` for row vectors (..., D): directions such as velocities, which do not translate."""
    rotation, vectors = np.asarray(rotation, dtype=np.float64), np.asarray(vectors, dtype=np.float64)
    d = vectors.shape[-1]
    return np.stack([sum(vectors[..., k] * rotation[..., e, k] for k in range(d)) for e in range(d)], axis=-1)


def apply(rotation, translation, points) -> np.ndarray:
    """``R p + t`` for row vectors (..., D)."""
    return rotate(rotation, points) + np.asarray(translation, dtype=np.float64)


def compose(first, second) -> tuple[np.ndarray, np.ndarray]:
    """The motion that applies `second` (R2, t2), then `first` (R1, t1): (R1 R2, R1 t2 + t1)."""
    (r1, t1), (r2, t2) = first, second
    r1 = np.asarray(r1, dtype=np.float64)
    return r1 @ np.asarray(r2, dtype=np.float64), rotate(r1, t2) + np.asarray(t1, dtype=np.float64)


def invert(rotation, translation) -> tuple[np.ndarray, np.ndarray]:
    """The inverse motion (R^T, -R^T t)."""
    back = np.swapaxes(np.asarray(rotation, dtype=np.float64), -1, -2)
    return back, -rotate(back, translation)


def chain(start, rotations, translations) -> tuple[np.ndarray, np.ndarray]:
    """Running compositions (K + 1, D, D), (K + 1, D): entry 0 is `start` (R0, t0) and entry k is
    entry k - 1 composed with step k - 1, ``compose(entry[k - 1], (rotations[k - 1], translations[k - 1]))``:
    the placement after each of K steps taken in order (a walk's transitions)."""
    rotation, translation = (np.asarray(x, dtype=np.float64) for x in start)
    rotations, translations = np.asarray(rotations, dtype=np.float64), np.asarray(translations, dtype=np.float64)
    d, k = rotation.shape[-1], len(rotations)
    if d == 2:
        # plane rotations compose by adding angles: no sequential matrix products
        angles = np.arctan2(rotations[:, 1, 0], rotations[:, 0, 0])
        total = np.arctan2(rotation[1, 0], rotation[0, 0]) + np.concatenate([[0.0], np.cumsum(angles)])
        placed = _plane(total)
    else:
        placed = np.empty((k + 1, 3, 3))
        placed[0] = rotation
        for step in range(k):
            placed[step + 1] = placed[step] @ rotations[step]
    steps = rotate(placed[:-1], translations) if k else np.zeros((0, d))
    return placed, translation + np.concatenate([np.zeros((1, d)), np.cumsum(steps, axis=0)])


def kabsch(target, source) -> np.ndarray:
    """Proper rotations R (..., D, D) minimizing ``sum_i |target_i - R source_i|^2`` for point sets
    (..., N, D), each already centered as the caller wants (Kabsch 1976; the reflection case is
    turned into the best proper rotation). Weighted terms are extra rows: scale them by sqrt(w)."""
    target, source = np.asarray(target, dtype=np.float64), np.asarray(source, dtype=np.float64)
    cross = (source[..., :, :, None] * target[..., :, None, :]).sum(axis=-3)  # sum_i s_i t_i^T
    if target.shape[-1] == 2:
        return _plane(np.arctan2(cross[..., 0, 1] - cross[..., 1, 0], cross[..., 0, 0] + cross[..., 1, 1]))
    u, _, vt = np.linalg.svd(cross)
    v = np.swapaxes(vt, -1, -2)
    ut = np.swapaxes(u, -1, -2)
    signs = np.ones(cross.shape[:-1])
    signs[..., -1] = np.where(np.linalg.det(v @ ut) < 0, -1.0, 1.0)
    return (v * signs[..., None, :]) @ ut


def turn(source, target) -> np.ndarray:
    """The smallest proper rotation taking the direction of vector `source` (D,) to that of
    `target`; the identity where either is too short (1e-12) to have a direction. Opposite
    directions in 3D turn half way round the axis perpendicular to `source` nearest a world axis."""
    source, target = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    d = len(source)
    a, b = np.linalg.norm(source), np.linalg.norm(target)
    if a < 1e-12 or b < 1e-12:
        return np.eye(d)
    u, v = source / a, target / b
    if d == 2:
        return _plane(np.arctan2(u[0] * v[1] - u[1] * v[0], u @ v))
    axis = np.cross(u, v)
    sine, cosine = np.linalg.norm(axis), float(u @ v)
    if sine < 1e-12:
        if cosine > 0:
            return np.eye(3)
        other = np.eye(3)[int(np.argmin(np.abs(u)))]
        axis = np.cross(u, other) / np.linalg.norm(np.cross(u, other))
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]) / sine
    return np.eye(3) + sine * k + (1 - cosine) * k @ k


def rotation(angle: float, axis=None) -> np.ndarray:
    """The rotation by `angle` radians: in 2D (no `axis`) counter-clockwise; in 3D about `axis`
    (3,), right-handed (Rodrigues' formula)."""
    if axis is None:
        return _plane(angle)
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def _plane(angle) -> np.ndarray:
    """Rotations (..., 2, 2) by `angle` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


# Quaternions are (..., 4) arrays (x, y, z, w), as glTF and scipy.spatial.transform store them.


def quaternion_product(a, b) -> np.ndarray:
    """The Hamilton product a b (..., 4): the rotation that applies `b`, then `a`."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b), -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    x, y, z, w = np.moveaxis(np.asarray(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def trs(translations, rotations, scales, *, dtype=np.float64) -> np.ndarray:
    """4 x 4 matrices T R S (..., 4, 4) from translations (..., 3), unit quaternions (..., 4) and
    scales (..., 3), broadcast against each other: a node's or a joint's local transform."""
    rotations = np.asarray(rotations).astype(dtype, copy=False)
    linear = quaternion_matrix(rotations) * np.asarray(scales, dtype=dtype)[..., None, :]
    m = np.zeros(linear.shape[:-2] + (4, 4), dtype=dtype)
    m[..., :3, :3] = linear
    m[..., :3, 3] = translations
    m[..., 3, 3] = 1.0
    return m


def slerp(a, b, u) -> np.ndarray:
    """Spherical interpolation of unit quaternions (..., 4) by `u` (broadcast against (..., 1)),
    the shorter way round."""
    a, b = np.asarray(a), np.asarray(b)
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    angle = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
    sine = np.sin(angle)
    near = sine < 1e-9
    wa = np.where(near, 1 - u, np.sin((1 - u) * angle) / np.where(near, 1, sine))
    wb = np.where(near, u, np.sin(u * angle) / np.where(near, 1, sine))
    return wa * a + wb * b


def nlerp(a, b, u) -> np.ndarray:
    """Normalized linear interpolation of unit quaternions (..., 4), the shorter way round: on the
    sphere like slerp, with the same ends, at a fraction of its cost (what game engines blend
    poses with)."""
    a, b = np.asarray(a), np.asarray(b)
    b = np.where(np.vecdot(a, b)[..., None] < 0, -b, b)  # vecdot: far faster than summing a * b over 4
    mixed = a + u * (b - a)
    return mixed / np.sqrt(np.vecdot(mixed, mixed))[..., None]


def facing(velocities) -> np.ndarray:
    """Unit quaternions (w, x, y, z) turning +x onto each of the 3D `velocities` (N, 3): the
    shortest turn, half a turn about z for -x, the identity for a still agent (what an exported
    agent faces)."""
    velocities = np.asarray(velocities, dtype=np.float64)
    speed = np.linalg.norm(velocities, axis=1, keepdims=True)
    u = np.divide(velocities, speed, out=np.tile([1.0, 0.0, 0.0], (len(velocities), 1)), where=speed > 1e-12)
    q = np.column_stack([1.0 + u[:, 0], np.zeros(len(u)), -u[:, 2], u[:, 1]])  # half-way rotation
    backwards = q[:, 0] < 1e-9
    q[backwards] = [0.0, 0.0, 0.0, 1.0]  # facing -x: half a turn about z
    return q / np.linalg.norm(q, axis=1, keepdims=True)
