"""Planar geometry of conflicts: the paper's closest point of approach (eqs. 3-4) and
distances between straight path segments. Pure numpy, no state.

No function here, and nothing in the simulator, hands a product of vectors to BLAS (``@``,
``np.dot``, ``np.linalg.norm`` of a whole vector): the BLAS library numpy ships picks its kernel
by the CPU, and its AVX-512 kernel adds ``x0*y0 + x1*y1`` with a fused multiply-add where the
AVX2 one does not, so a day came out 1e-13 apart on two machines. :func:`dot` and
:func:`length` add the products left to right in plain double arithmetic, the same on every
CPU (and the same numbers the AVX2 kernel gives)."""

from __future__ import annotations

import math

import numpy as np

_EPS = 1e-12


def dot(u, v) -> float:
    """``u . v`` of two short vectors (the products added left to right, no BLAS)."""
    total = float(u[0]) * float(v[0])
    for i in range(1, len(u)):
        total += float(u[i]) * float(v[i])
    return total


def length(u) -> float:
    """``|u|`` of a short vector: ``sqrt(dot(u, u))``."""
    return math.sqrt(dot(u, u))


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
    dp = (np.asarray(p1, dtype=float) - np.asarray(p2, dtype=float)).tolist()
    dv = (np.asarray(v1, dtype=float) - np.asarray(v2, dtype=float)).tolist()
    return cpa(dp, dv)


def cpa(dp: list[float], dv: list[float]) -> tuple[float, float]:
    """:func:`closest_approach` on the relative position ``dp`` and velocity ``dv`` given as
    plain sequences of floats (the scalar core, used on hot paths)."""
    dv2 = sum(c * c for c in dv)
    if dv2 <= _EPS:
        return 0.0, math.sqrt(sum(c * c for c in dp))
    t_min = -sum(a * b for a, b in zip(dp, dv)) / dv2
    return t_min, math.sqrt(sum((a + t_min * b) ** 2 for a, b in zip(dp, dv)))


def plan_crossing(ax: float, ay: float, ux: float, uy: float, cx: float, cy: float,
                  vx: float, vy: float, eps: float) -> bool:
    """Whether the 2-D segments from ``(ax, ay)`` along ``(ux, uy)`` and from ``(cx, cy)``
    along ``(vx, vy)`` cross; segments within ``eps`` of parallel are not counted as crossing
    (the distances of their ends decide)."""
    den = ux * vy - uy * vx
    if abs(den) > eps:
        ex, ey = cx - ax, cy - ay
        s = (ex * vy - ey * vx) / den
        t = (ex * uy - ey * ux) / den
        return 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0
    return False


def segment_distance(a0: tuple, a1: tuple, b0: tuple, b1: tuple) -> float:
    """Smallest distance between the 2-D segments ``a0-a1`` and ``b0-b1`` (metres); zero when
    they intersect. Degenerate segments (points) are allowed."""
    dax, day = a1[0] - a0[0], a1[1] - a0[1]
    dbx, dby = b1[0] - b0[0], b1[1] - b0[1]
    if plan_crossing(a0[0], a0[1], dax, day, b0[0], b0[1], dbx, dby, _EPS):
        return 0.0
    return min(_point_segment(a0, b0, dbx, dby), _point_segment(a1, b0, dbx, dby),
               _point_segment(b0, a0, dax, day), _point_segment(b1, a0, dax, day))


def segments_within(a0: tuple, a1: tuple, b0: tuple, b1: tuple, limit: float) -> bool:
    """``segment_distance(a0, a1, b0, b1) < limit``, with the same float operations: the four
    end-to-segment distances are compared with ``limit`` as they are computed (their least is
    below it when one of them is), so a close pair is known at the first that says so."""
    dax, day = a1[0] - a0[0], a1[1] - a0[1]
    dbx, dby = b1[0] - b0[0], b1[1] - b0[1]
    if plan_crossing(a0[0], a0[1], dax, day, b0[0], b0[1], dbx, dby, _EPS):
        return 0.0 < limit
    return (_point_segment(a0, b0, dbx, dby) < limit or _point_segment(a1, b0, dbx, dby) < limit
            or _point_segment(b0, a0, dax, day) < limit
            or _point_segment(b1, a0, dax, day) < limit)


def _point_segment(pt: tuple, s0: tuple, dx: float, dy: float) -> float:
    dd = dx * dx + dy * dy
    u = 0.0
    if dd > _EPS:
        u = min(1.0, max(0.0, ((pt[0] - s0[0]) * dx + (pt[1] - s0[1]) * dy) / dd))
    return math.hypot(pt[0] - s0[0] - u * dx, pt[1] - s0[1] - u * dy)


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
    moved = end - start  # each vehicle's displacement, gathered per pair below
    dp = start.take(pairs_i, axis=0) - start.take(pairs_j, axis=0)
    dv = moved.take(pairs_i, axis=0) - moved.take(pairs_j, axis=0)
    dv2 = np.einsum("ij,ij->i", dv, dv)
    moving = dv2 > _EPS
    t = np.where(moving, -np.einsum("ij,ij->i", dp, dv) / np.where(moving, dv2, 1.0), 0.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)  # np.clip's values, without its wrapper's cost
    closest = dp + t[:, None] * dv
    return np.sqrt(np.einsum("ij,ij->i", closest, closest))


def swept_min_distance_pair(a0: tuple, a1: tuple, b0: tuple, b1: tuple) -> float:
    """Scalar :func:`swept_min_distance` of one pair: vehicle A from ``a0`` to ``a1`` and B from
    ``b0`` to ``b1`` (3-tuples, metres) over the same interval. Cheaper than the array version
    for the few pairs of a small fleet."""
    return swept_min_distances((a0, b0), (a1, b1), ((0, 1),))[0]


def swept_min_distances(start, end, pairs) -> list[float]:
    """Scalar :func:`swept_min_distance` of many pairs: ``start`` and ``end`` hold each vehicle's
    position (``[x, y, z]``, metres) at the start and the end of the interval, ``pairs`` the
    ``(i, j)`` index pairs; one distance per pair, in order. For a few dozen pairs a loop over
    Python floats is cheaper than the array version."""
    out = []
    for i, j in pairs:
        a0, a1, b0, b1 = start[i], end[i], start[j], end[j]
        dx, dy, dz = a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2]
        vx = (a1[0] - a0[0]) - (b1[0] - b0[0])
        vy = (a1[1] - a0[1]) - (b1[1] - b0[1])
        vz = (a1[2] - a0[2]) - (b1[2] - b0[2])
        vv = vx * vx + vy * vy + vz * vz
        t = 0.0
        if vv > _EPS:
            t = min(1.0, max(0.0, -(dx * vx + dy * vy + dz * vz) / vv))
        out.append(math.sqrt((dx + t * vx) ** 2 + (dy + t * vy) ** 2 + (dz + t * vz) ** 2))
    return out
