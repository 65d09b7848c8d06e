"""Protected volumes, the geometry of the separation check (:mod:`~marl_vertiport.sim.clearance`):
chains of vertical and level segments extended behind each start, the test of two volumes
against the separation thresholds per axis, and the memos of those tests that every simulator
of one geometry in a process shares. Pure functions and plain containers; no simulator state.
"""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.geometry import plan_crossing

#: A segment of a volume: plan-view start and end, and the altitude range it spans,
#: ``(ax, ay, bx, by, z_low, z_high)`` in metres (margins applied).
Segment = tuple[float, float, float, float, float, float]
Volume = tuple[Segment, ...]

_EPS = 1e-9
#: Entries kept in a memo of pure volume tests before it is emptied (bounds memory on long runs).
MEMO_MAX = 20_000


def volume(start, waypoints, margin_m: float, floor_z_m: float) -> Volume:
    """The protected volume of a flight from ``start`` through ``waypoints`` (``(x, y, z)`` each):
    one segment per leg, extended ``margin_m`` behind its start along its direction (a vertical
    leg in altitude, no lower than ``floor_z_m``). A flight without waypoints is the point
    ``start``."""
    x0, y0, z0 = float(start[0]), float(start[1]), float(start[2])
    if not len(waypoints):
        return ((x0, y0, x0, y0, z0, z0),)
    segs = []
    for w in waypoints:
        x1, y1, z1 = float(w[0]), float(w[1]), float(w[2])
        dx, dy = x1 - x0, y1 - y0
        h = math.hypot(dx, dy)
        if h > _EPS:  # a level leg (every horizontal leg flown is level)
            segs.append((x0 - dx / h * margin_m, y0 - dy / h * margin_m, x1, y1,
                         z0 if z0 < z1 else z1, z1 if z0 < z1 else z0))
        elif z1 > z0 + _EPS:  # a climb: the margin below its start
            low = z0 - margin_m
            segs.append((x0, y0, x1, y1, low if low > floor_z_m else floor_z_m, z1))
        elif z1 < z0 - _EPS:  # a descent: the margin above its start
            segs.append((x0, y0, x1, y1, z1, z0 + margin_m))
        else:
            segs.append((x0, y0, x0, y0, z0, z0))
        x0, y0, z0 = x1, y1, z1
    return tuple(segs)


def _point_segment_sq(px, py, ax, ay, bx, by) -> float:
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    u = 0.0
    if dd > _EPS:
        u = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / dd))
    ex, ey = px - ax - u * dx, py - ay - u * dy
    return ex * ex + ey * ey


def plan_distance(s: Segment, t: Segment) -> float:
    """Distance of the plan-view projections of two segments (0 where they cross)."""
    ax, ay, bx, by = s[0], s[1], s[2], s[3]
    cx, cy, dx, dy = t[0], t[1], t[2], t[3]
    ux, uy, vx, vy = bx - ax, by - ay, dx - cx, dy - cy
    if plan_crossing(ax, ay, ux, uy, cx, cy, vx, vy, _EPS):
        return 0.0
    return math.sqrt(min(_point_segment_sq(ax, ay, cx, cy, dx, dy),
                         _point_segment_sq(bx, by, cx, cy, dx, dy),
                         _point_segment_sq(cx, cy, ax, ay, bx, by),
                         _point_segment_sq(dx, dy, ax, ay, bx, by)))


def segments_clear(s: Segment, t: Segment, h_m: float, v_m: float) -> bool:
    """Whether two segments keep ``v_m`` apart in altitude or ``h_m`` apart in plan view:
    ``plan_distance(s, t) >= h_m`` where the altitude ranges are closer, with the same float
    operations and answer. Each of the four point-to-segment distances is compared with ``h_m``
    as it is computed (``sqrt`` of their least is the least of their ``sqrt``), so a pair that
    is too close is known at the first distance that says so."""
    if s[4] - t[5] >= v_m or t[4] - s[5] >= v_m:
        return True
    ax, ay, bx, by = s[0], s[1], s[2], s[3]
    cx, cy, dx, dy = t[0], t[1], t[2], t[3]
    # Plan-view boxes h_m apart along x or y: the segments are at least that far apart.
    sx0, sx1 = (ax, bx) if ax <= bx else (bx, ax)
    tx0, tx1 = (cx, dx) if cx <= dx else (dx, cx)
    if sx0 - tx1 >= h_m or tx0 - sx1 >= h_m:
        return True
    sy0, sy1 = (ay, by) if ay <= by else (by, ay)
    ty0, ty1 = (cy, dy) if cy <= dy else (dy, cy)
    if sy0 - ty1 >= h_m or ty0 - sy1 >= h_m:
        return True
    # plan_distance, inlined: a crossing, then the ends of each against the other (the loop is
    # _point_segment_sq written out: four calls of it cost about 5 % of a step on `large`).
    ux, uy, vx, vy = bx - ax, by - ay, dx - cx, dy - cy
    if plan_crossing(ax, ay, ux, uy, cx, cy, vx, vy, _EPS):
        return 0.0 >= h_m
    sqrt = math.sqrt
    for px, py, qx, qy, wx, wy in ((ax, ay, cx, cy, vx, vy), (bx, by, cx, cy, vx, vy),
                                   (cx, cy, ax, ay, ux, uy), (dx, dy, ax, ay, ux, uy)):
        dd = wx * wx + wy * wy
        u = 0.0
        if dd > _EPS:
            u = ((px - qx) * wx + (py - qy) * wy) / dd
            u = 0.0 if not u > 0.0 else (u if u < 1.0 else 1.0)  # min(1, max(0, u))
        ex, ey = px - qx - u * wx, py - qy - u * wy
        if not sqrt(ex * ex + ey * ey) >= h_m:
            return False
    return True


def volumes_clear(a: Volume, b: Volume, h_m: float, v_m: float) -> bool:
    """Whether every segment of ``a`` is clear of every segment of ``b``."""
    for s in a:
        for t in b:
            if not segments_clear(s, t, h_m, v_m):
                return False
    return True


class TaxiMoves:
    """The moves from one node to every other node, for testing them against one reservation
    (:meth:`fill`, :meth:`clear_of`): their distinct segments (the climb from the node begins
    every move, so it is tested once a call), each move's segments and box, and the box around
    all of them.

    Args:
        volumes: by target node, the volume of the move there (``()`` for the node itself).
    """

    def __init__(self, volumes: list[Volume]) -> None:
        index: dict[Segment, int] = {}
        #: By target node, ``(segment indices, box)`` of the move there, or ``None`` (the node
        #: itself).
        self.moves: list[tuple[tuple[int, ...], tuple] | None] = [
            (tuple([index.setdefault(seg, len(index)) for seg in vol]), box(vol)) if vol else None
            for vol in volumes]
        self.segments = list(index)
        #: The box around every move: that of all their segments (``None`` where there is no
        #: move).
        self.around = box(tuple(self.segments)) if self.segments else None
        #: int8 ``(P,)``: 1 at every target (the clearances where nothing is in the way).
        self.free = np.asarray([m is not None for m in self.moves], dtype=np.int8)
        self.free.setflags(write=False)
        self._free_list = self.free.tolist()

    def fill(self, ok: list[int] | np.ndarray, targets: list[int], other: Volume, other_box: tuple,
             h_m: float, v_m: float) -> None:
        """Set ``ok[k]`` (``P`` ints, a list or an array) for each node ``k`` of ``targets``: 1
        where the move to ``k`` clears ``other`` (whose :func:`box` is ``other_box``), as the
        box test and :func:`volumes_clear` say, else 0 (and 0 at the node itself)."""
        if self.around is None or boxes_apart(self.around, other_box, h_m, v_m):
            # No move, or every move's box is as far apart as the box around them.
            free = self._free_list
            for k in targets:
                ok[k] = free[k]
            return
        seg_ok: list[bool | None] = [None] * len(self.segments)
        segments, moves = self.segments, self.moves
        for k in targets:
            move = moves[k]
            if move is None:
                ok[k] = 0
                continue
            idx, bx = move
            if boxes_apart(bx, other_box, h_m, v_m):
                ok[k] = 1
                continue
            ok[k] = 1
            for i in idx:
                clear = seg_ok[i]
                if clear is None:
                    seg = segments[i]
                    clear = True
                    for t in other:
                        if not segments_clear(seg, t, h_m, v_m):
                            clear = False
                            break
                    seg_ok[i] = clear
                if not clear:
                    ok[k] = 0
                    break

    def clear_of(self, other: Volume, other_box: tuple, h_m: float, v_m: float) -> np.ndarray:
        """Read-only int8 ``(P,)``: :meth:`fill` at every node."""
        ok = np.zeros(len(self.moves), dtype=np.int8)
        self.fill(ok, list(range(len(self.moves))), other, other_box, h_m, v_m)
        ok.setflags(write=False)
        return ok


class VolumeMemo:
    """Memos of pure functions of a vertiport's geometry and of reservations, shared by every
    simulator of that geometry in a process (an env's copies, a planner's look-ahead sims, the
    worker of an evaluation): the volumes named by small ints, their boxes, and which
    clearances clear which reservation. ``gen`` counts the times it was emptied; a simulator
    that finds it changed names its reservations again (:meth:`Clearance._check_memo`)."""

    def __init__(self) -> None:
        self.volume_ids: dict[Volume, int] = {}
        self.volumes: list[Volume] = []
        self.boxes: list[tuple] = []
        self.node_ok: dict[tuple[int, int], list[int]] = {}  # -1: not tested yet
        self.trip_ok: dict[tuple[int, int, int], bool] = {}
        self.taxi_volumes: dict[int, list[Volume]] = {}
        self.taxi_moves: dict[int, TaxiMoves] = {}
        self.trip_volumes: dict[tuple[int, int], Volume] = {}
        self.trip_boxes: dict[tuple[int, int], tuple] = {}
        self.lifted: dict[tuple[int, int, bool], int] = {}
        self.pair_ok: dict[tuple[int, int], bool] = {}
        self.avoid: dict[tuple, int | None] = {}
        self.hold: dict[tuple, bool] = {}
        self.route_ids: dict[tuple, int] = {}
        self.flights: dict[tuple, tuple] = {}
        self.masks: dict[tuple, list] = {}  # [keep mask, the nodes tested]
        self.spots: dict[tuple, int] = {}
        self.slot_order: dict[tuple, list[int]] = {}
        self.slot_ids: dict[int, list[int]] = {}
        self.slot_routes: dict[tuple, tuple] = {}
        self.releases: dict[tuple, tuple] = {}
        self.gen = 0

    def _tables(self) -> list[dict | list]:
        return [t for t in vars(self).values() if isinstance(t, (dict, list))]

    def size(self) -> int:
        """Entries in the largest table."""
        return max(len(t) for t in self._tables())

    def clear(self) -> None:
        """Empty every table and count it in ``gen``."""
        for table in self._tables():
            table.clear()
        self.gen += 1


#: The memos by geometry, the most recently used last (a few layouts at a time).
_MEMOS: dict[tuple, VolumeMemo] = {}
_MEMOS_KEPT = 8


def shared_memo(key: tuple) -> VolumeMemo:
    memo = _MEMOS.pop(key, None) or VolumeMemo()
    _MEMOS[key] = memo
    while len(_MEMOS) > _MEMOS_KEPT:
        del _MEMOS[next(iter(_MEMOS))]
    return memo


def box(vol: Volume) -> tuple[float, float, float, float, float, float]:
    """Bounding box ``(x_lo, x_hi, y_lo, y_hi, z_lo, z_hi)`` of a volume."""
    if len(vol) == 1:  # the most common: a point or one leg
        s = vol[0]
        return (min(s[0], s[2]), max(s[0], s[2]), min(s[1], s[3]), max(s[1], s[3]), s[4], s[5])
    xs = [c for s in vol for c in (s[0], s[2])]
    ys = [c for s in vol for c in (s[1], s[3])]
    return (min(xs), max(xs), min(ys), max(ys), min(s[4] for s in vol), max(s[5] for s in vol))


def boxes_apart(a: tuple, b: tuple, h_m: float, v_m: float) -> bool:
    """Whether bounding boxes ``a`` and ``b`` (:func:`box`) are ``h_m`` apart along x or y, or
    ``v_m`` apart in altitude: then every segment of one volume is clear of every segment of the
    other (the quick test before :func:`volumes_clear`)."""
    return (a[0] - b[1] >= h_m or b[0] - a[1] >= h_m or a[2] - b[3] >= h_m
            or b[2] - a[3] >= h_m or a[4] - b[5] >= v_m or b[4] - a[5] >= v_m)
