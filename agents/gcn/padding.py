"""Observations to the graph models' inputs: the one converter from observation arrays to the
tensors the actor and critic read (:func:`to_tensordict`), padding graph observations of
different vertiports to one size, and actions back.

Training across scenarios mixes vertiports with different numbers of nodes ``P`` and eVTOLs
``N`` in one batch (rsl_rl's rollout storage and the imitation data hold fixed-shape tensors).
Each observation is padded to the largest ``P_max`` and ``N_max`` with zero rows, and the
boolean groups ``port_valid (P_max,)`` and ``evtol_valid (N_max,)`` mark the real rows (the GCN
models leave padded nodes out, see agents/gcn/models.py).

The action space ``[stay, take off, node 0 .. node P-1, continue, avoid]`` grows with ``P``:
in the padded space the node actions run to ``P_max`` and continue/avoid come after them. Padded
node actions are masked. :func:`to_padded_action` and :func:`from_padded_action` convert.
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDict

from marl_vertiport.sim.schema import LEADING_ACTIONS



def pad_rows(x: np.ndarray, size: int, axis: int) -> np.ndarray:
    """``x`` with zero rows appended along ``axis`` up to ``size``."""
    missing = size - x.shape[axis]
    if missing < 0:
        raise ValueError(f"cannot pad {x.shape[axis]} rows to {size}")
    if missing == 0:
        return x
    widths = [(0, 0)] * x.ndim
    widths[axis] = (0, missing)
    return np.pad(x, widths)


def pad_action_mask(mask: np.ndarray, n_nodes: int, max_nodes: int) -> np.ndarray:
    """A mask ``(..., 4 + P)`` as ``(..., 4 + P_max)``, padded node actions illegal."""
    lead = mask[..., : LEADING_ACTIONS + n_nodes]
    tail = mask[..., LEADING_ACTIONS + n_nodes:]
    pad = np.zeros(mask.shape[:-1] + (max_nodes - n_nodes,), dtype=mask.dtype)
    return np.concatenate([lead, pad, tail], axis=-1)


def to_padded_action(action: np.ndarray | int, n_nodes: int, max_nodes: int):
    """An action of the ``P``-node space in the ``P_max``-node space."""
    a = np.asarray(action)
    out = np.where(a >= LEADING_ACTIONS + n_nodes, a + (max_nodes - n_nodes), a)
    return int(out) if out.ndim == 0 else out


def from_padded_action(action: np.ndarray | int, n_nodes: int, max_nodes: int):
    """An action of the ``P_max``-node space in the ``P``-node space (padded node actions are
    masked, so they never arrive here; one that does is refused)."""
    a = np.asarray(action)
    if np.any((a >= LEADING_ACTIONS + n_nodes) & (a < LEADING_ACTIONS + max_nodes)):
        raise ValueError(f"action {a.tolist()} targets a padded node (the vertiport has {n_nodes})")
    out = np.where(a >= LEADING_ACTIONS + max_nodes, a - (max_nodes - n_nodes), a)
    return int(out) if out.ndim == 0 else out


def pad_observation(arrays: dict[str, np.ndarray], max_nodes: int, max_evtols: int
                    ) -> dict[str, np.ndarray]:
    """One observation's groups (``port_nodes (P, Fp)``, ``evtol_nodes (N, Fe)``, ``self``,
    ``action_mask (4 + P)``, any leading dims) padded to ``P_max`` nodes and ``N_max`` eVTOLs,
    with ``port_valid`` and ``evtol_valid``; other groups pass through."""
    out = dict(arrays)
    ports = arrays["port_nodes"]
    evtols = arrays["evtol_nodes"]
    p, n = ports.shape[-2], evtols.shape[-2]
    lead = ports.shape[:-2]
    out["port_nodes"] = pad_rows(ports, max_nodes, -2)
    out["evtol_nodes"] = pad_rows(evtols, max_evtols, -2)
    out["action_mask"] = pad_action_mask(arrays["action_mask"], p, max_nodes)
    out["port_valid"] = np.broadcast_to(np.arange(max_nodes) < p, lead + (max_nodes,)).copy()
    out["evtol_valid"] = np.broadcast_to(np.arange(max_evtols) < n, lead + (max_evtols,)).copy()
    return out


#: Groups that are masks (bool tensors); every other group is features (float32).
BOOL_GROUPS = ("action_mask", "port_valid", "evtol_valid")


def to_tensordict(arrays: dict[str, np.ndarray], batch_size: int, device: str | torch.device = "cpu"
                  ) -> TensorDict:
    """Observation groups with a leading batch dimension (``port_nodes (B, P, Fp)``,
    ``evtol_nodes (B, N, Fe)``, ``self (B, Fs)``, ``action_mask (B, A)``, and any state or
    ``*_valid`` groups) as the models' input: features as float32, masks as bool, copied (the
    arrays may be reused)."""
    data = {}
    for key, value in arrays.items():
        tensor = torch.from_numpy(np.array(value, copy=True))
        data[key] = tensor.bool() if key in BOOL_GROUPS else tensor.float()
    return TensorDict(data, batch_size=[batch_size], device=device)


def example_observation(kind: str = "observation") -> TensorDict:
    """A batch of one zero observation with one vertiport node and one eVTOL, the groups a
    graph model of ``kind`` reads (``"observation"``: the actor's three groups and its action
    mask; ``"state"``: the centralised critic's). The models are size-agnostic, so this is all
    they need to be built; no env is made."""
    from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS, feature_names
    from marl_vertiport.sim.schema import ActionLayout

    names = feature_names(kind)
    groups = POLICY_GROUPS if kind == "observation" else STATE_GROUPS
    arrays = {groups[0]: np.zeros((1, 1, len(names["ports"])), np.float32),
              groups[1]: np.zeros((1, 1, len(names["evtols"])), np.float32),
              groups[2]: np.zeros((1, len(names["extra"])), np.float32)}
    if kind == "observation":
        arrays["action_mask"] = np.ones((1, ActionLayout(1).n), bool)
    return to_tensordict(arrays, 1)
