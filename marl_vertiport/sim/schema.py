"""The simulator's vocabulary, defined once: vehicle statuses, schedule statuses, pending
operations, the feature columns of the graphs and the action layout (the paper's table I).

Everything that reads an observation or builds an action (the env APIs, the controllers, the
graph models, the tests) takes these from here.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from marl_vertiport.sim.layout import Layout


class Status(enum.IntEnum):
    """A vehicle's status: feature ``status`` of the eVTOL graph."""

    ON_PORT = 0
    ON_CHARGER = 1
    HOVERING = 2
    TAXIING = 3
    DEPARTING = 4
    AWAY = 5
    ARRIVING = 6
    OUT_OF_SERVICE = 7


# Plain ints of the statuses, for the hot paths and for indexing per-status tables.
ON_PORT, ON_CHARGER, HOVERING, TAXIING, DEPARTING, AWAY, ARRIVING, OUT_OF_SERVICE = (
    int(s) for s in Status)
#: Status names by code (``STATUS_NAMES[HOVERING] == "hovering"``).
STATUS_NAMES = tuple(s.name.lower() for s in Status)
#: By status code (indexed by a Python int on hot paths): in the air, so a flat battery is a
#: depletion in flight.
AIRBORNE = (False, False, True, True, True, True, True, False)
#: By status code: flying inside the airspace, so in the ATC's conflict probe.
IN_TRANSIT_INSIDE = (False, False, False, True, True, False, True, False)

# Schedule status codes (feature ``schedule_status``).
EARLY, ON_TIME, DELAYED = -1, 0, 1
# Pending operation of a vehicle.
NO_OPERATION, PENDING_TAKEOFF, PENDING_LANDING = 0, 1, 2

#: Columns of the eVTOL graph's node features in observations.
EVTOL_FEATURES = ("status", "battery_pct", "schedule_status", "x_m", "y_m", "z_m", "vx_mps",
                  "vy_mps", "minutes_to_schedule", "delay_min", "conflict", "node", "is_self")
#: Columns of the acting eVTOL's own feature vector (``self`` in observations).
SELF_FEATURES = EVTOL_FEATURES[:11]
_IS_SELF = EVTOL_FEATURES.index("is_self")
#: Columns of the vertiport graph's node features (paper: availability, type, location).
PORT_FEATURES = ("available", "type", "x_m", "y_m")
#: Extra columns of the eVTOL nodes in the global state, after EVTOL_FEATURES.
STATE_EXTRA_FEATURES = ("vz_mps", "destination_x_m", "destination_y_m", "avoid_layer")
#: Extra column of the port nodes in the global state: index of the occupying/reserving vehicle.
STATE_PORT_FEATURES = PORT_FEATURES + ("occupant",)
#: Entries of the ``clock`` array of the global state.
CLOCK_FEATURES = ("minute", "acting_vehicle", "steps_left")

#: Actions before the node actions: stay, take off.
LEADING_ACTIONS = 2
#: Actions after the node actions: continue, avoid.
TRAILING_ACTIONS = 2


@dataclass
class ActionLayout:
    """Indices of the discrete actions for a vertiport of ``n_nodes`` nodes (paper's table I
    order): ``[stay, take off, node 0 .. node n_nodes-1, continue, avoid]``."""

    n_nodes: int
    stay: int = 0
    takeoff: int = 1
    continue_: int = field(init=False)
    avoid: int = field(init=False)

    def __post_init__(self) -> None:
        self.continue_ = LEADING_ACTIONS + self.n_nodes
        self.avoid = self.continue_ + 1

    @property
    def n(self) -> int:
        return LEADING_ACTIONS + self.n_nodes + TRAILING_ACTIONS

    def node_action(self, node: int) -> int:
        """Action that moves to / lands on vertiport node ``node``."""
        return LEADING_ACTIONS + node

    def names(self, layout: Layout) -> list[str]:
        out = ["stay", "takeoff"]
        for k in range(layout.n_normal):
            out.append(f"normal_port_{k}")
        for k in range(layout.n_charging):
            out.append(f"charging_port_{k}")
        for k in range(layout.n_hover):
            out.append(f"hover_spot_{k}")
        return out + ["continue", "avoid_collision"]


def format_actions(actions: Any, names: list[str]) -> str:
    """Actions as error messages list them: ``"0 (stay), 1 (takeoff), 4 (charging_port_0)"``
    (``names``: :meth:`ActionLayout.names`); ``"none"`` for an empty list."""
    shown = [f"{int(a)} ({names[int(a)]})" if 0 <= int(a) < len(names) else str(int(a))
             for a in actions]
    return ", ".join(shown) if shown else "none"
