"""Safety: the ATC's conflict probe (paper eqs. 3-5) and the separation actually flown.

**Conflict probe.** For every pair of vehicles in transit inside the airspace, with planned
horizontal velocities ``v_a``, ``v_b`` (toward the current waypoint at cruise speed) and positions
``p_a``, ``p_b``, take ``dp = p_a - p_b`` and ``dv = v_a - v_b``:

    t_min = -(dp . dv) / |dv|^2          (eq. 4; 0 when dv = 0)
    D_min = |dp + t_min dv|              (eq. 3 at t_min)

The pair conflicts when their legs are less than the separation apart in altitude, their planned
2-D paths come within the separation distance of each other (the paper's "intersecting paths",
for vehicles with a footprint), ``t_min >= 0`` and ``D_min <= separation``. The safety term of
the reward (eq. 5, :mod:`marl_vertiport.sim.reward`) reads the acting vehicle's flag.

**Separation flown.** A loss of separation is a pair whose minimum distance over the step, with
both moving linearly between their start and end positions, is below the separation.

docs/reward-and-safety.md, section 7. The geometry is :mod:`marl_vertiport.sim.geometry`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from marl_vertiport.sim.geometry import (
    _EPS, segments_within, swept_min_distance, swept_min_distances,
)

#: Above this many vehicle pairs the array version of the swept distance is cheaper.
SCALAR_PAIRS_MAX = 24

XY = tuple[float, float]


def planned_velocity(position_xy: XY, target_xy: XY, speed_mps: float) -> XY:
    """Horizontal velocity toward ``target_xy`` at ``speed_mps`` (0 when already above it)."""
    dx, dy = target_xy[0] - position_xy[0], target_xy[1] - position_xy[1]
    d = math.hypot(dx, dy)
    return (dx / d * speed_mps, dy / d * speed_mps) if d > 1e-9 else (0.0, 0.0)


def conflicting_pairs(vehicles: Sequence[int], start: dict[int, XY], end: dict[int, XY],
                      velocity: dict[int, XY], leg_alt_m: Sequence[float], separation_m: float
                      ) -> list[tuple[int, int]]:
    """The pairs of ``vehicles`` in a predicted conflict.

    Args:
        vehicles: the vehicles in transit inside the airspace.
        start, end: per vehicle, its position now and the end of its planned path (x, y).
        velocity: per vehicle, its planned horizontal velocity (m/s).
        leg_alt_m: per vehicle (indexed by vehicle), the altitude of its leg.
        separation_m: the minimum separation.
    """
    pairs = []
    sqrt = math.sqrt
    for i, a in enumerate(vehicles):
        sa, ea, va, alt = start[a], end[a], velocity[a], leg_alt_m[a]
        for b in vehicles[i + 1:]:
            if abs(alt - leg_alt_m[b]) >= separation_m:
                continue
            # The closest approach (cpa, eqs. 3-4, inline: the same float operations), then the
            # paths; both must hold, the cheaper is tested first.
            sb, vb = start[b], velocity[b]
            dpx, dpy = sa[0] - sb[0], sa[1] - sb[1]
            dvx, dvy = va[0] - vb[0], va[1] - vb[1]
            dv2 = dvx * dvx + dvy * dvy
            if dv2 <= _EPS:
                if sqrt(dpx * dpx + dpy * dpy) > separation_m:
                    continue  # t_min = 0
            else:
                t_min = -(dpx * dvx + dpy * dvy) / dv2
                if t_min < 0.0 or sqrt((dpx + t_min * dvx) ** 2
                                       + (dpy + t_min * dvy) ** 2) > separation_m:
                    continue
            if segments_within(sa, ea, sb, end[b], separation_m):
                pairs.append((a, b))
    return pairs


def swept_distances_m(prev_pos: np.ndarray, pos: np.ndarray, pairs: list[tuple[int, int]],
                      prev_rows: list[list[float]] | None = None,
                      rows: list[list[float]] | None = None) -> list[float]:
    """Per pair, the least distance (m) of the two vehicles over the step, both moving linearly
    from ``prev_pos`` to ``pos`` (``(N, 3)`` each). ``prev_rows`` and ``rows``: the same
    positions as lists, where the caller has them (the few pairs of a small fleet are measured
    on lists, many on the arrays)."""
    if len(pairs) > SCALAR_PAIRS_MAX:
        pi = np.fromiter((a for a, _ in pairs), dtype=np.int64, count=len(pairs))
        pj = np.fromiter((b for _, b in pairs), dtype=np.int64, count=len(pairs))
        return swept_min_distance(prev_pos, pos, pi, pj).tolist()
    return swept_min_distances(prev_pos.tolist() if prev_rows is None else prev_rows,
                               pos.tolist() if rows is None else rows, pairs)
