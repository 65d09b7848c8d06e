"""Observations to torch-geometric batches, without a Python loop per graph.

Every observation of one env has the same node counts and edge counts, so a batch of ``B``
observations is a reshape: node features ``(B, P, F)`` become ``(B*P, F)``, and the edges of
sample ``b`` are shifted by ``b*P``. The result equals ``Batch.from_data_list`` of the
per-sample graphs (a test checks this), at a fraction of the cost.

torch and torch-geometric are imported when a batch is first made: importing this module, or
the env, loads neither.

Accepted inputs: one AEC/Gymnasium observation (arrays without a batch dimension), a list of
them, or a batched observation (leading dimension ``B``, e.g. from a vector env), with numpy
arrays or torch tensors. Both ``{"observation": {...}, "action_mask": ...}`` and the inner
``{...}`` dict are accepted.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # torch and torch-geometric load when a batch is made, not on import
    import torch
    from torch_geometric.data import Batch

_GRAPH_KEYS = ("port_nodes", "evtol_nodes", "self")
_UNBATCHED_NDIM = {"port_nodes": 2, "evtol_nodes": 2, "self": 1, "action_mask": 1}


def complete_edge_index(n: int) -> np.ndarray:
    """Edges of a complete directed graph without self-loops, shape ``(2, n (n - 1))``: both
    graphs of an observation are complete (docs/observations.md, section 5.4)."""
    src, dst = np.nonzero(~np.eye(n, dtype=bool))
    return np.stack([src, dst]).astype(np.int64)


@dataclass
class GraphObservation:
    """A batch of ``B`` observations as graphs.

    Attributes:
        ports: vertiport graphs, ``x`` of shape ``(B*P, F_port)``, ``edge_index`` ``(2, B*E_p)``,
            ``batch`` ``(B*P,)``.
        evtols: eVTOL graphs, ``x`` ``(B*N, F_evtol)``, ``edge_index`` ``(2, B*E_e)``,
            ``batch`` ``(B*N,)``.
        self_features: ``(B, F_self)`` features of the acting eVTOL.
        action_mask: ``(B, A)`` bool, True = legal; ``None`` if the input had no mask.
    """

    ports: Batch
    evtols: Batch
    self_features: torch.Tensor
    action_mask: torch.Tensor | None

    @property
    def num_graphs(self) -> int:
        return self.self_features.shape[0]


def _as_tensor(value: Any, device: torch.device | str | None) -> torch.Tensor:
    import torch

    if isinstance(value, torch.Tensor):
        return value.to(device) if device is not None else value
    return torch.as_tensor(np.asarray(value), device=device)


def _collate(obs: Any) -> dict[str, Any]:
    """Flatten the observation's nesting and stack a list of observations."""
    if isinstance(obs, Sequence) and not isinstance(obs, (str, bytes)):
        if len(obs) == 0:
            raise ValueError("cannot batch an empty list of observations")
        items = [_collate(o) for o in obs]
        for item in items:
            for key, value in item.items():
                if np.ndim(value) != _UNBATCHED_NDIM[key]:
                    raise ValueError(f"{key}: a list must hold unbatched observations")
        out: dict[str, Any] = {}
        for key in items[0]:
            values = [item[key] for item in items]
            if type(values[0]).__module__.startswith("torch"):
                import torch

                out[key] = torch.stack(values)
            else:
                out[key] = np.stack(values)
        return out
    if not isinstance(obs, Mapping):
        raise TypeError(f"expected an observation dict or a list of them, got {type(obs).__name__}")
    inner = obs.get("observation", obs)
    missing = [k for k in _GRAPH_KEYS if k not in inner]
    if missing:
        raise KeyError(f"observation lacks {missing}; expected keys {list(_GRAPH_KEYS)}")
    out = {k: inner[k] for k in _GRAPH_KEYS}
    if "action_mask" in obs:
        out["action_mask"] = obs["action_mask"]
    return out


def _graph_batch(nodes: torch.Tensor) -> Batch:
    """``nodes (B, K, F)`` -> one PyG batch of ``B`` complete graphs of ``K`` nodes."""
    import torch
    from torch_geometric.data import Batch

    b, k, f = nodes.shape
    device = nodes.device
    edges = torch.as_tensor(complete_edge_index(k), device=device)  # (2, E)
    offsets = (torch.arange(b, device=device) * k).view(b, 1, 1)
    edge_index = (edges.unsqueeze(0) + offsets).permute(1, 0, 2).reshape(2, -1)
    batch = torch.arange(b, device=device).repeat_interleave(k)
    ptr = torch.arange(b + 1, device=device) * k
    out = Batch(x=nodes.reshape(b * k, f).float(), edge_index=edge_index, batch=batch, ptr=ptr)
    out._num_graphs = b
    return out


def to_graph_batch(obs: Any, device: torch.device | str | None = None) -> GraphObservation:
    """Turn observations into torch-geometric batches (see the module docstring)."""
    data = _collate(obs)
    tensors = {k: _as_tensor(v, device) for k, v in data.items()}
    if tensors["port_nodes"].dim() == 2:  # a single unbatched observation
        tensors = {k: v.unsqueeze(0) for k, v in tensors.items()}
    mask = tensors.get("action_mask")
    return GraphObservation(
        ports=_graph_batch(tensors["port_nodes"]),
        evtols=_graph_batch(tensors["evtol_nodes"]),
        self_features=tensors["self"].float(),
        action_mask=mask.bool() if mask is not None else None,
    )


def to_state_batch(state: Any, device: torch.device | str | None = None) -> tuple[Batch, Batch, torch.Tensor]:
    """The global ``state()`` (one, a list, or batched) as ``(ports, evtols, clock)``."""
    if isinstance(state, Sequence):
        stacked = {k: np.stack([np.asarray(s[k]) for s in state]) for k in state[0]}
        state = stacked
    t = {k: _as_tensor(v, device) for k, v in state.items()}
    if t["port_nodes"].dim() == 2:
        t = {k: v.unsqueeze(0) for k, v in t.items()}
    return _graph_batch(t["port_nodes"]), _graph_batch(t["evtol_nodes"]), t["clock"].float()
