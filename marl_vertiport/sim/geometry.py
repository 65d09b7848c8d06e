"""Planar geometry of conflicts: the paper's closest point of approach (eqs. 3-4) and
distances between straight path segments. Pure numpy, no state."""

from __future__ import annotations

import math

import numpy as np

_EPS = 1e-12


def closest_approach(
    p1: np.ndarray, v1: np.ndarray, p2: np.ndarray, v2: np.ndarray
) -> tuple[float, float]:
    """Time and distance of the closest approach of two vehicles in straight motion.

    The paper's eqs. 3-4: with ``dp = p1 - p2`` and ``dv = v1 - v2``, the distance
    ``D(t) = |dp + t dv|`` is smallest at ``t_min = -(dp . dv) / |dv|^2`` and
    ``D_min = D(t_min)``. ``t_min`` may be negative (the vehicles are moving apart).
    With identical velocities the distance never changes: ``t_min = 0``, ``D_min = |dp|``.

    Args:
        p1, p2: positions in metres, shape ``(2,)`` (or ``(3,)``).
        v1, v2: velocities in m/s, same shape.

    Returns:
        ``(t_min, d_min)`` in seconds and metres.
    """
    dp = np.asarray(p1, dtype=float) - np.asarray(p2, dtype=float)
    dv = np.asarray(v1, dtype=float) - np.asarray(v2, dtype=float)
    dv2 = float(dv @ dv)
    if dv2 <= _EPS:
        return 0.0, float(np.sqrt(dp @ dp))
    t_min = -float(dp @ dv) / dv2
    closest = dp + t_min * dv
    return t_min, float(np.sqrt(closest @ closest))


def closest_approach_many(
    p: np.ndarray, v: np.ndarray, others_p: np.ndarray, others_v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`closest_approach` of one vehicle against ``K`` others.

    Args:
        p, v: shape ``(2,)``; others_p, others_v: shape ``(K, 2)``.

    Returns:
        ``t_min`` and ``d_min``, each of shape ``(K,)``.
    """
    dp = p[None, :] - others_p
    dv = v[None, :] - others_v
    dv2 = np.einsum("ij,ij->i", dv, dv)
    moving = dv2 > _EPS
    t_min = np.where(moving, -np.einsum("ij,ij->i", dp, dv) / np.where(moving, dv2, 1.0), 0.0)
    closest = dp + t_min[:, None] * dv
    return t_min, np.sqrt(np.einsum("ij,ij->i", closest, closest))


def segment_distance_many(
    a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
) -> np.ndarray:
    """Smallest distance between segment ``a0-a1`` and each segment ``b0[k]-b1[k]`` in 2-D.

    Zero when the segments intersect. Degenerate segments (points) are allowed.

    Args:
        a0, a1: shape ``(2,)``; b0, b1: shape ``(K, 2)``.

    Returns:
        Distances in metres, shape ``(K,)``.
    """
    a0 = np.broadcast_to(a0, b0.shape)
    a1 = np.broadcast_to(a1, b0.shape)
    da = a1 - a0
    db = b1 - b0

    def cross(u: np.ndarray, w: np.ndarray) -> np.ndarray:
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    denom = cross(da, db)
    diff = b0 - a0
    safe = np.where(np.abs(denom) > _EPS, denom, 1.0)
    s = cross(diff, db) / safe
    t = cross(diff, da) / safe
    intersect = (np.abs(denom) > _EPS) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)

    def point_to_segment(pt: np.ndarray, s0: np.ndarray, d: np.ndarray) -> np.ndarray:
        dd = np.einsum("ij,ij->i", d, d)
        u = np.where(dd > _EPS, np.einsum("ij,ij->i", pt - s0, d) / np.where(dd > _EPS, dd, 1.0), 0.0)
        u = np.clip(u, 0.0, 1.0)
        closest = s0 + u[:, None] * d
        return np.linalg.norm(pt - closest, axis=1)

    dist = np.minimum.reduce([
        point_to_segment(a0, b0, db),
        point_to_segment(a1, b0, db),
        point_to_segment(b0, a0, da),
        point_to_segment(b1, a0, da),
    ])
    return np.where(intersect, 0.0, dist)


def swept_min_distance(
    start: np.ndarray, end: np.ndarray, pairs_i: np.ndarray, pairs_j: np.ndarray
) -> np.ndarray:
    """Smallest distance between vehicle pairs while each moved in a straight line from
    ``start`` to ``end`` over the same interval (3-D).

    Args:
        start, end: positions at the start and end of the interval, shape ``(N, 3)``.
        pairs_i, pairs_j: indices of the pairs, shape ``(K,)``.

    Returns:
        Minimum centre distance of each pair over the interval, shape ``(K,)``.
    """
    dp = start[pairs_i] - start[pairs_j]
    dv = (end[pairs_i] - start[pairs_i]) - (end[pairs_j] - start[pairs_j])
    dv2 = np.einsum("ij,ij->i", dv, dv)
    t = np.where(dv2 > _EPS, -np.einsum("ij,ij->i", dp, dv) / np.where(dv2 > _EPS, dv2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    closest = dp + t[:, None] * dv
    return np.sqrt(np.einsum("ij,ij->i", closest, closest))


def swept_min_distance_pair(a0: tuple, a1: tuple, b0: tuple, b1: tuple) -> float:
    """Scalar :func:`swept_min_distance` of one pair: vehicle A from ``a0`` to ``a1`` and B from
    ``b0`` to ``b1`` (3-tuples, metres) over the same interval. Cheaper than the array version
    for the few pairs of a small fleet."""
    dx, dy, dz = a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2]
    vx = (a1[0] - a0[0]) - (b1[0] - b0[0])
    vy = (a1[1] - a0[1]) - (b1[1] - b0[1])
    vz = (a1[2] - a0[2]) - (b1[2] - b0[2])
    vv = vx * vx + vy * vy + vz * vz
    t = 0.0
    if vv > _EPS:
        t = min(1.0, max(0.0, -(dx * vx + dy * vy + dz * vz) / vv))
    return math.sqrt((dx + t * vx) ** 2 + (dy + t * vy) ** 2 + (dz + t * vz) ** 2)
