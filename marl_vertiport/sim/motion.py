"""Motion: every vehicle with a target flies toward it for one step at cruise speed (pybullet
inside the airspace, a kinematic model outside it), with the wind gusts of case 2; the
vehicles that reach a waypoint go on to the next one or finish their leg.
"""

from __future__ import annotations

import math

from marl_vertiport.sim.schema import AWAY

_DEFLECTION_TOL_M = 1e-4  # engine position vs commanded motion; integration error is ~1e-12


class Motion:
    """One step of flight of :class:`~marl_vertiport.sim.core.VertiportSim` (a part of it)."""

    def _move(self, status: list[int], start: list[list[float]]) -> tuple[int, list[list[float]]]:
        """Move every vehicle with a target for one step.

        Args:
            status: per vehicle, its status code during the step, ``N`` ints.
            start: per vehicle, its position at the start of the step, ``N`` lists ``[x, y, z]``.

        Returns:
            The number of gusts, and per vehicle its position at the end of the step (``N``
            lists; the vehicles that did not move share their row of ``start``).

        Fills ``self._moved`` (vehicles that had a target), ``self._moved_m`` (distance each
        flew this step) and ``self._deflected`` (bodies the engine pushed off their commanded
        motion: only a contact can do that, gusts are accounted for exactly).

        The per-vehicle work is scalar arithmetic on Python lists in the loop that makes the
        per-body engine calls anyway: for fleets of a few dozen it is several times cheaper than
        numpy on arrays of that size (measured; see docs/performance.md).
        """
        moving = self.has_target.nonzero()[0].tolist()
        moved_m: list[float] = []
        deflected: list[int] = []
        self._moved, self._moved_m, self._deflected = moving, moved_m, deflected
        if self._any_cmd_vel:
            self.cmd_vel[:] = 0.0
        self._any_cmd_vel = bool(moving)
        if not moving:
            return 0, start
        dt, step_len, park_z = self.dt_s, self.step_len_m, self.park_z_m
        draws = self.draws
        keep, n_gusts = self.uncertainty.gust_factors(
            self.rng, len(moving),
            None if draws is None else (draws.gust_hit_u[moving], draws.gust_loss_u[moving]))
        targets = self.target.tolist()
        pos, cmd_vel = self.pos, self.cmd_vel
        radius = self.layout.airspace_radius_m
        # Rules v1: a reversing gust pushes a vehicle back along its segment no farther than
        # the margin behind the segment's start (its protected volume, sim/clearance.py).
        seg_from = self.seg_from.tolist() if self.sep_check and keep is not None else None
        margin = self.margin_m
        end = list(start)
        lead = self.leaders if self.trail else None
        bodies, body_vel, body_keep = [], [], []
        for k, v in enumerate(moving):
            px, py, pz = start[v]
            tx, ty, tz = targets[v]
            dx, dy, dz = tx - px, ty - py, tz - pz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            scale = (step_len / dist if dist > step_len else 1.0) / dt
            vel = (dx * scale, dy * scale, dz * scale)
            if lead is not None and lead[v] and status[v] != AWAY and self._must_hold(
                    v, (px, py, pz), (px + vel[0] * dt, py + vel[1] * dt, pz + vel[2] * dt)):
                vel = (0.0, 0.0, 0.0)  # trailing a departure: hold until the way clears
                self.metrics.trail_hold_min += self.minutes_per_step
            cmd_vel[v] = vel
            f = 1.0 if keep is None else keep[k]
            if f < 0.0 and vel[2] > 0.0 and pz + vel[2] * dt * f < park_z:
                # The ground stops a reversing gust: a vehicle climbing from its pad is pushed
                # back down to the pad at most, never below it.
                f = (park_z - pz) / (vel[2] * dt)
            if f < 0.0 and seg_from is not None and status[v] != AWAY:
                sx, sy, sz = seg_from[v]
                ux, uy, uz = tx - sx, ty - sy, tz - sz
                seg_m = math.sqrt(ux * ux + uy * uy + uz * uz)
                fly_m = math.sqrt(vel[0] * vel[0] + vel[1] * vel[1] + vel[2] * vel[2]) * dt
                if seg_m > 1e-9 and fly_m > 1e-12:
                    along = ((px - sx) * ux + (py - sy) * uy + (pz - sz) * uz) / seg_m
                    f = max(f, (-margin - along) / fly_m)
            if status[v] == AWAY:
                nx, ny, nz = px + vel[0] * dt * f, py + vel[1] * dt * f, pz + vel[2] * dt * f
                r = math.hypot(nx, ny)
                if f < 0.0 and r < radius and not self.returning[v]:
                    # A reversing gust pushed an outbound vehicle back toward the airspace:
                    # it holds at the boundary (it would otherwise be inside without a body).
                    nx, ny = nx * radius / r, ny * radius / r
                pos[v] = end[v] = [nx, ny, nz]
            else:
                bodies.append(v)
                body_vel.append(vel)
                body_keep.append(f)
        if bodies:
            new_pos = self.physics.step(bodies, body_vel, None if keep is None else body_keep)
            for v, p, vel, f in zip(bodies, new_pos, body_vel, body_keep):
                s = start[v]
                pos[v] = end[v] = [p[0], p[1], p[2]]
                off = max(abs(p[0] - s[0] - vel[0] * dt * f), abs(p[1] - s[1] - vel[1] * dt * f),
                          abs(p[2] - s[2] - vel[2] * dt * f))
                if off > _DEFLECTION_TOL_M:
                    deflected.append(v)
        for v in moving:
            moved_m.append(math.dist(end[v], start[v]))
        return n_gusts, end

    def _process_arrivals(self, end: list[list[float]]) -> int:
        """Advance routes of vehicles that reached their waypoint; returns touchdowns.

        ``end``: per vehicle, its position after this step's motion (``N`` lists)."""
        if not self._moved:
            return 0
        touchdowns = 0
        targets = self.target.tolist()
        release_at = self.release_at if self.sep_check else None
        for v in self._moved:
            p, t = end[v], targets[v]
            if max(abs(p[0] - t[0]), abs(p[1] - t[1]), abs(p[2] - t[2])) >= 1e-6:
                if release_at is not None:
                    q = release_at[v]  # the quick test of _advance_reservation, inline
                    if q is not None and ((p[0] - q[0]) * q[3] + (p[1] - q[1]) * q[4]
                                          + (p[2] - q[2]) * q[5]) >= q[6]:
                        self._advance_reservation(v, p, t)
                continue
            if self.routes[v]:
                self.seg_from[v] = self.target[v]
                self.target[v] = self.routes[v].pop(0)
                self._reserve(v)
                continue
            self.has_target[v] = False
            touchdowns += self._finish_leg(v)
        return touchdowns
