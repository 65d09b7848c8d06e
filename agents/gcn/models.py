"""The paper's GCN policy as rsl_rl models.

``GraphActor`` and ``GraphCritic`` subclass rsl_rl's ``MLPModel``: rsl_rl builds the MLP head
(the paper's 128-64, RReLU 0.1-0.3), the output distribution and every property PPO uses; only
the latent differs. Instead of concatenating flat observation groups, the latent is a graph
encoding: one GCN over the vertiport graph and one over the eVTOL graph (complete graphs), both
mean-pooled, with the embedding of the eVTOL the model acts or judges for, its own feature
vector, and the availability of each vertiport node (whose identity the node actions refer to).

Observation groups (names in ``obs_groups[obs_set]``, in this order): port-node features
``(B, P, Fp)``, eVTOL-node features ``(B, N, Fe)``, and a vector ``(B, Fx)`` (the acting eVTOL's
own features for the actor, the clock for the centralised critic). Feature columns are named by
``port_features`` / ``evtol_features`` / ``extra_features`` so that each is scaled to about
unit range, and categorical ones (status, node type) are one-hot encoded.

Shapes: the latent is ``(B, 4 * hidden + P)``; the actor outputs ``(B, 1)`` actions, the
critic ``(B, 1)`` values.
"""

from __future__ import annotations

import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict
from torch import nn
from torch_geometric.nn import DenseGCNConv

from agents.gcn.distribution import MaskedCategorical

#: Scale of each numeric feature (divide by it); names as in marl_vertiport.sim.core.
FEATURE_SCALES = {
    "available": 1.0, "x_m": 40.0, "y_m": 40.0, "z_m": 16.0, "battery_pct": 100.0,
    "schedule_status": 1.0, "vx_mps": 8.0, "vy_mps": 8.0, "vz_mps": 8.0,
    "minutes_to_schedule": 20.0, "delay_min": 20.0, "conflict": 1.0, "node": 10.0, "is_self": 1.0,
    "occupant": 4.0, "destination_x_m": 40.0, "destination_y_m": 40.0, "avoid_layer": 2.0,
    "minute": 1440.0, "acting_vehicle": 4.0, "steps_left": 1440.0,
}
#: Categorical features and their number of categories (one-hot encoded).
ONE_HOT = {"status": 8, "type": 3}


class FeatureEncoder(nn.Module):
    """Scales numeric columns and one-hot encodes categorical ones: ``(..., F) -> (..., F')``."""

    def __init__(self, names: tuple[str, ...]) -> None:
        super().__init__()
        numeric = [i for i, n in enumerate(names) if n not in ONE_HOT]
        unknown = [names[i] for i in numeric if names[i] not in FEATURE_SCALES]
        if unknown:
            raise ValueError(f"no scale for features {unknown}")
        self.register_buffer("numeric_idx", torch.tensor(numeric, dtype=torch.long))
        self.register_buffer("scales", torch.tensor([FEATURE_SCALES[names[i]] for i in numeric]))
        self.categorical = [(i, ONE_HOT[n]) for i, n in enumerate(names) if n in ONE_HOT]
        self.out_dim = len(numeric) + sum(k for _, k in self.categorical)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        parts = [x.index_select(-1, self.numeric_idx) / self.scales]
        for col, k in self.categorical:
            parts.append(nn.functional.one_hot(x[..., col].long().clamp(0, k - 1), k).to(x.dtype))
        return torch.cat(parts, dim=-1)


class GraphGCN(nn.Module):
    """Two GCN layers with RReLU over a batch of complete graphs ``(B, K, F)``.

    Uses torch-geometric's dense GCN layer (``D^-1/2 (A + I) D^-1/2 X W`` with a batched
    adjacency): for the small complete graphs of a vertiport it is the same layer as the sparse
    ``GCNConv`` at a fraction of the cost. Returns node embeddings ``(B, K, H)`` and their mean
    over the nodes ``(B, H)``.
    """

    def __init__(self, in_dim: int, hidden: int) -> None:
        super().__init__()
        self.conv1 = DenseGCNConv(in_dim, hidden)
        self.conv2 = DenseGCNConv(hidden, hidden)
        self.act = nn.RReLU(0.1, 0.3)

    def forward(self, nodes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        k = nodes.shape[1]
        adj = 1.0 - torch.eye(k, device=nodes.device, dtype=nodes.dtype)  # complete graph
        x = self.act(self.conv1(nodes, adj))
        x = self.act(self.conv2(x, adj))
        return x, x.mean(dim=1)


class GraphEncoder(nn.Module):
    """Both graphs and the extra vector to one latent vector ``(B, out_dim)``."""

    def __init__(self, port_features: tuple[str, ...], evtol_features: tuple[str, ...],
                 extra_features: tuple[str, ...], num_ports: int, hidden: int = 64) -> None:
        super().__init__()
        self.port_enc = FeatureEncoder(port_features)
        self.evtol_enc = FeatureEncoder(evtol_features)
        self.extra_enc = FeatureEncoder(extra_features)
        self.port_gcn = GraphGCN(self.port_enc.out_dim, hidden)
        self.evtol_gcn = GraphGCN(self.evtol_enc.out_dim, hidden)
        self.extra = nn.Sequential(nn.Linear(self.extra_enc.out_dim, hidden), nn.RReLU(0.1, 0.3))
        self.is_self_col = evtol_features.index("is_self")
        self.available_col = port_features.index("available")
        self.out_dim = 4 * hidden + num_ports

    def forward(self, ports: torch.Tensor, evtols: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
        port_nodes, port_pool = self.port_gcn(self.port_enc(ports))
        evtol_nodes, evtol_pool = self.evtol_gcn(self.evtol_enc(evtols))
        is_self = evtols[..., self.is_self_col].unsqueeze(-1)  # (B, N, 1), one-hot over N
        self_node = (evtol_nodes * is_self).sum(dim=1)
        return torch.cat([port_pool, evtol_pool, self_node, self.extra(self.extra_enc(extra)),
                          ports[..., self.available_col]], dim=-1)


class _GraphModel(MLPModel):
    """``MLPModel`` whose latent is a :class:`GraphEncoder` of three observation groups."""

    def __init__(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str,
                 output_dim: int, feature_names: dict[str, list[str]], hidden: int = 64,
                 hidden_dims: tuple[int, ...] | list[int] = (128, 64),
                 distribution_cfg: dict | None = None) -> None:
        self._feature_names = feature_names
        self._hidden = hidden
        # "lrelu" is a placeholder: rsl_rl has no RReLU; it is swapped in below.
        super().__init__(obs, obs_groups, obs_set, output_dim, hidden_dims=hidden_dims,
                         activation="lrelu", obs_normalization=False,
                         distribution_cfg=distribution_cfg)
        for i, module in enumerate(self.mlp):
            if isinstance(module, nn.LeakyReLU):
                self.mlp[i] = nn.RReLU(0.1, 0.3)
        self.train(self.training)  # fix the RReLU slopes from the start (see train())

    def train(self, mode: bool = True) -> _GraphModel:
        """RReLU draws random slopes in training mode, which would make the log-probabilities
        PPO compares between rollout and update differ by noise: its slopes stay at their mean
        (0.2) in training too."""
        super().train(mode)
        for module in self.modules():
            if isinstance(module, nn.RReLU):
                module.eval()
        return self

    def _get_obs_dim(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str):
        groups = list(obs_groups[obs_set])
        if len(groups) != 3:
            raise ValueError(f"{type(self).__name__} needs 3 observation groups for {obs_set!r} "
                             f"(port nodes, eVTOL nodes, a vector), got {groups}")
        names = self._feature_names
        ports, evtols, extra = (obs[g] for g in groups)
        for group, tensor, dims, key in ((groups[0], ports, 3, "ports"), (groups[1], evtols, 3, "evtols"),
                                         (groups[2], extra, 2, "extra")):
            if tensor.dim() != dims or tensor.shape[-1] != len(names[key]):
                raise ValueError(f"group {group!r} has shape {tuple(tensor.shape)}, expected "
                                 f"{dims} dims with {len(names[key])} features ({key})")
        self.encoder = GraphEncoder(tuple(names["ports"]), tuple(names["evtols"]),
                                    tuple(names["extra"]), ports.shape[1], self._hidden)
        return groups, self.encoder.out_dim

    def get_latent(self, obs: TensorDict, masks=None, hidden_state=None) -> torch.Tensor:
        ports, evtols, extra = (obs[g] for g in self.obs_groups)
        return self.encoder(ports.float(), evtols.float(), extra.float())


class GraphActor(_GraphModel):
    """Shared GCN actor: legal-action-masked logits -> :class:`MaskedCategorical`.

    Args (beyond rsl_rl's): ``feature_names`` (column names of the three groups),
    ``mask_group`` (the observation group holding the legal-action mask), ``hidden``.
    """

    def __init__(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str,
                 output_dim: int, feature_names: dict[str, list[str]], mask_group: str = "action_mask",
                 hidden: int = 64, hidden_dims: tuple[int, ...] | list[int] = (128, 64),
                 distribution_cfg: dict | None = None) -> None:
        if mask_group not in obs.keys():
            raise ValueError(f"mask group {mask_group!r} is not among the observations {list(obs.keys())}")
        self.mask_group = mask_group
        dist_cfg = dict(distribution_cfg or {"class_name": "agents.gcn.distribution:MaskedCategorical"})
        dist_cfg.setdefault("num_choices", obs[mask_group].shape[-1])
        super().__init__(obs, obs_groups, obs_set, output_dim, feature_names, hidden, hidden_dims,
                         dist_cfg)
        if not isinstance(self.distribution, MaskedCategorical):
            raise TypeError("GraphActor needs a MaskedCategorical-compatible distribution, got "
                            f"{type(self.distribution).__name__}")

    def logits(self, obs: TensorDict) -> torch.Tensor:
        """Unmasked logits ``(B, A)``."""
        return self.mlp(self.get_latent(obs))

    def action_probabilities(self, obs: TensorDict) -> torch.Tensor:
        """``(B, A)`` probabilities, 0 on illegal actions."""
        self.distribution.update(self.logits(obs), obs[self.mask_group])
        return self.distribution.probs

    def forward(self, obs: TensorDict, masks=None, hidden_state=None,
                stochastic_output: bool = False) -> torch.Tensor:
        logits = self.logits(obs)
        mask = obs[self.mask_group]
        if stochastic_output:
            self.distribution.update(logits, mask)
            return self.distribution.sample()
        return self.distribution.deterministic_output(logits, mask)


class GraphCritic(_GraphModel):
    """Value network over a graph observation (the global ``state()`` for the centralised
    critic of the multi-agent mode, the acting eVTOL's observation in the single-agent mode)."""
