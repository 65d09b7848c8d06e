"""The simulator's state as graph features (the paper's section III-A): the vertiport graph
(availability, type, position of every node), the eVTOL graph (status, battery, schedule
status, position, planned velocity, minutes to the scheduled operation, delay, conflict flag,
node, ``is_self``), an eVTOL's own feature vector, and the global, noise-free state a
centralised critic reads. The observation builders (:mod:`marl_vertiport.spaces`) turn them
into observations.
"""

from __future__ import annotations

import numpy as np

from marl_vertiport.sim.schema import (
    EVTOL_FEATURES, NO_OPERATION, STATE_EXTRA_FEATURES, STATE_PORT_FEATURES, _IS_SELF,
)


class Features:
    """Graph features of :class:`~marl_vertiport.sim.core.VertiportSim` (a part of it)."""

    def schedule_status(self) -> np.ndarray:
        """-1 early, 0 on time, 1 delayed, per vehicle, shape ``(N,)``."""
        return self.schedule.status_codes(self.minute, self.pending_time, self.pending_kind)

    def evtol_features(self) -> np.ndarray:
        """The eVTOL graph's node features ``(N, 13)`` float32, ``is_self`` 0, cached until the
        next step and read-only (an observation marks its own vehicle in a copy).

        Built as one flat list of Python numbers, converted to float32 in one call (a flat list
        converts about twice as fast as nested rows): for the paper's 4 vehicles about a third
        of the cost of a dozen column assignments and the array masks of
        :meth:`schedule_status` (which gives the same column), for 16 about the same cost."""
        if self._evtol_cache is None:
            status_code = self.schedule.status_code
            values: list[float] = []
            # _rel_min holds minute - pending_time, as of the last step.
            for st, bat, pk, rel, (ox, oy), (_, _, z), (vx, vy), d, c, nd in zip(
                    self.status.tolist(), self.battery.tolist(), self.pending_kind.tolist(),
                    self._rel_min.tolist(), self.obs_xy.tolist(),
                    self.pos.tolist(), self.plan_vel_xy.tolist(), self.delay.tolist(),
                    self.conflict.tolist(), self.node.tolist()):
                values += (st, bat, status_code(rel, pk), ox, oy, z, vx, vy,
                           -rel if pk != NO_OPERATION else 0.0, d, c, nd, 0.0)
            cache = np.array(values, dtype=np.float32).reshape(self.n, len(EVTOL_FEATURES))
            cache.setflags(write=False)
            self._evtol_cache = cache
        return self._evtol_cache

    def port_features(self) -> np.ndarray:
        """The vertiport graph's node features ``(P, 4)`` float32: available, type, x_m, y_m;
        built once a step, read-only."""
        if self._port_cache is None:
            f = self._port_static.copy()
            f[:, 0] = self.node_occupant == -1
            f.setflags(write=False)
            self._port_cache = f
        return self._port_cache

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The global, noise-free graph a centralised critic reads: ``port_nodes (P, 5)`` (the
        vertiport graph and each node's occupant), ``evtol_nodes (N, 17)`` (the eVTOL graph at
        the true positions, ``is_self`` marking the acting vehicle, with vertical speed,
        destination and avoidance layer) and ``clock (3,)`` (minute, acting vehicle, steps
        left); new arrays."""
        base = self.evtol_features()
        evtol = np.empty((self.n, len(EVTOL_FEATURES) + len(STATE_EXTRA_FEATURES)), dtype=np.float32)
        evtol[:, : len(EVTOL_FEATURES)] = base
        evtol[:, 3:5] = self.pos[:, :2]
        evtol[:, _IS_SELF] = 0.0
        evtol[self.acting, _IS_SELF] = 1.0
        k = len(EVTOL_FEATURES)
        evtol[:, k] = self.cmd_vel[:, 2]
        evtol[:, k + 1:k + 3] = self.layout.destination_xy_m[self.dest]
        evtol[:, k + 3] = self.avoid_layer
        ports = np.empty((self.layout.n_nodes, len(STATE_PORT_FEATURES)), dtype=np.float32)
        ports[:, :4] = self.port_features()
        ports[:, 4] = self.node_occupant
        clock = np.array([self.minute, self.acting,
                          self.cfg.schedule.episode_steps - self.step_count], dtype=np.float32)
        return {"port_nodes": ports, "evtol_nodes": evtol, "clock": clock}
