"""What the graph models read: the observation groups of the actor and the critic, and the
column names of each (the feature schema a checkpoint stores and is checked against)."""

from __future__ import annotations

from marl_vertiport.sim.schema import (
    CLOCK_FEATURES, EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES, STATE_EXTRA_FEATURES,
    STATE_PORT_FEATURES,
)

#: Observation groups the actor reads (one eVTOL's view of the vertiport).
POLICY_GROUPS = ("port_nodes", "evtol_nodes", "self")
#: Groups the centralised critic reads (``state()``, the global graph).
STATE_GROUPS = ("state_port_nodes", "state_evtol_nodes", "state_clock")


def feature_names(kind: str) -> dict[str, list[str]]:
    """Column names of the three groups a graph model reads: ``kind`` ``"observation"`` (the
    actor's, or an independent critic's) or ``"state"`` (the centralised critic's)."""
    if kind == "observation":
        return {"ports": list(PORT_FEATURES), "evtols": list(EVTOL_FEATURES), "extra": list(SELF_FEATURES)}
    return {"ports": list(STATE_PORT_FEATURES), "evtols": list(EVTOL_FEATURES) + list(STATE_EXTRA_FEATURES),
            "extra": list(CLOCK_FEATURES)}
