"""The paper's GCN policy as rsl_rl models, for any vertiport layout and fleet size.

``GraphActor`` and ``GraphCritic`` subclass rsl_rl's ``MLPModel``: rsl_rl builds the MLP head
(the paper's 128-64, RReLU 0.1-0.3), the output distribution and every property PPO uses; only
the latent and (for the actor) the action scores differ. The latent is a graph encoding: one GCN
over the vertiport graph and one over the eVTOL graph (complete graphs), both mean-pooled, with
the embedding of the eVTOL the model acts or judges for and an embedding of the extra vector.
Its width does not depend on the number of nodes.

**Actions.** The actor scores the four actions that name no node (stay, take off, continue,
avoid) with the MLP head on the latent, and each node action "go to node k" with a second MLP
on node ``k``'s embedding and encoded features, the embedding of the acting eVTOL's own
features and their relative position (metres):
``(B, 4 + P)`` logits for ``P`` nodes, whatever ``P`` is. Reordering the eVTOLs leaves each
one's action distribution unchanged; reordering nodes permutes the node-action probabilities
the same way (tested).

**Sizes.** A batch may mix vertiports of different sizes, padded to the largest: the optional
groups ``port_valid (B, P)`` and ``evtol_valid (B, N)`` (bool) mark the real nodes; padded ones
take no part in the convolutions or the pooling, and their actions are masked. Without them
every node is real.

Observation groups (names in ``obs_groups[obs_set]``, in this order): port-node features
``(B, P, Fp)``, eVTOL-node features ``(B, N, Fe)``, and a vector ``(B, Fx)`` (the acting eVTOL's
own features for the actor, the clock for the centralised critic). Feature columns are named by
``port_features`` / ``evtol_features`` / ``extra_features``; each is scaled by a fixed physical
unit (metres, minutes, percent: never the fleet or the layout size), categorical ones (status,
node type) are one-hot encoded, and index-valued ones (a node or vehicle number) are not read
as numbers: the acting vehicle's index becomes an ``is_acting`` flag on its eVTOL node.

Shapes: the latent is ``(B, 4 * hidden)``; the actor outputs ``(B, 1)`` actions, the critic
``(B, 1)`` values.
"""

from __future__ import annotations

import math

import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict
from torch import nn
from torch_geometric.nn import DenseGCNConv

from agents.gcn.distribution import MaskedCategorical
from marl_vertiport.sim.schema import LEADING_ACTIONS, TRAILING_ACTIONS

#: Scale of each numeric feature (divide by it), in physical units; names as in
#: marl_vertiport.sim.core.
FEATURE_SCALES = {
    "available": 1.0, "x_m": 40.0, "y_m": 40.0, "z_m": 16.0, "battery_pct": 100.0,
    "schedule_status": 1.0, "vx_mps": 8.0, "vy_mps": 8.0, "vz_mps": 8.0,
    "minutes_to_schedule": 20.0, "delay_min": 20.0, "conflict": 1.0, "is_self": 1.0,
    "destination_x_m": 40.0, "destination_y_m": 40.0, "avoid_layer": 2.0,
    "minute": 1440.0, "steps_left": 1440.0,
}
#: Categorical features and their number of categories (one-hot encoded).
ONE_HOT = {"status": 8, "type": 3}
#: Index-valued features: not read as numbers (their scale would depend on the fleet or the
#: layout); ``acting_vehicle`` becomes the ``is_acting`` flag of an eVTOL node.
INDEX_FEATURES = ("node", "occupant", "acting_vehicle")
#: Number of actions that name no node: stay, take off (before the node actions), continue,
#: avoid (after them).
FIXED_ACTIONS = LEADING_ACTIONS + TRAILING_ACTIONS
#: Node-action input beyond the two embeddings: node minus eVTOL position (x, y) and distance.
_RELATIVE = 3


class FeatureEncoder(nn.Module):
    """Scales numeric columns and one-hot encodes categorical ones: ``(..., F) -> (..., F')``;
    index-valued columns are left out."""

    def __init__(self, names: tuple[str, ...]) -> None:
        super().__init__()
        numeric = [i for i, n in enumerate(names) if n not in ONE_HOT and n not in INDEX_FEATURES]
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


def complete_adjacency(valid: torch.Tensor) -> torch.Tensor:
    """``(B, K, K)`` adjacency of the complete graph on each row's valid nodes (no self-loops)."""
    v = valid.to(torch.float32)
    adj = v.unsqueeze(-1) * v.unsqueeze(-2)
    return adj * (1.0 - torch.eye(valid.shape[-1], device=valid.device))


def masked_mean(x: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean of ``x (B, K, H)`` over the valid nodes ``(B, K)`` -> ``(B, H)`` (0 if none)."""
    w = valid.to(x.dtype).unsqueeze(-1)
    return (x * w).sum(dim=1) / w.sum(dim=1).clamp_min(1.0)


class GraphGCN(nn.Module):
    """Two GCN layers with RReLU over a batch of complete graphs ``(B, K, F)``.

    Uses torch-geometric's dense GCN layer (``D^-1/2 (A + I) D^-1/2 X W`` with a batched
    adjacency and a node mask): for the small complete graphs of a vertiport it is the same
    layer as the sparse ``GCNConv`` at a fraction of the cost, and it takes batches padded to
    one size. Returns node embeddings ``(B, K, H)`` (0 on padded nodes) and their mean over the
    valid nodes ``(B, H)``.
    """

    def __init__(self, in_dim: int, hidden: int) -> None:
        super().__init__()
        self.conv1 = DenseGCNConv(in_dim, hidden)
        self.conv2 = DenseGCNConv(hidden, hidden)
        self.act = nn.RReLU(0.1, 0.3)

    def forward(self, nodes: torch.Tensor, valid: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        if valid is None:
            valid = torch.ones(nodes.shape[:2], dtype=torch.bool, device=nodes.device)
        adj = complete_adjacency(valid).to(nodes.dtype)
        x = self.act(self.conv1(nodes, adj, mask=valid))
        x = self.act(self.conv2(x, adj, mask=valid)) * valid.unsqueeze(-1).to(nodes.dtype)
        return x, masked_mean(x, valid)


class GraphEncoder(nn.Module):
    """Both graphs and the extra vector to one latent vector ``(B, 4 * hidden)``; also keeps
    the node embeddings of the last call for the node actions."""

    def __init__(self, port_features: tuple[str, ...], evtol_features: tuple[str, ...],
                 extra_features: tuple[str, ...], hidden: int = 64) -> None:
        super().__init__()
        self.acting_col = (extra_features.index("acting_vehicle")
                           if "acting_vehicle" in extra_features else None)
        self.port_enc = FeatureEncoder(port_features)
        self.evtol_enc = FeatureEncoder(evtol_features)
        self.extra_enc = FeatureEncoder(extra_features)
        evtol_in = self.evtol_enc.out_dim + (1 if self.acting_col is not None else 0)
        self.port_gcn = GraphGCN(self.port_enc.out_dim, hidden)
        self.evtol_gcn = GraphGCN(evtol_in, hidden)
        self.extra = nn.Sequential(nn.Linear(self.extra_enc.out_dim, hidden), nn.RReLU(0.1, 0.3))
        self.is_self_col = evtol_features.index("is_self")
        self.port_xy_cols = [port_features.index("x_m"), port_features.index("y_m")]
        self.out_dim = 4 * hidden

    def forward(self, ports: torch.Tensor, evtols: torch.Tensor, extra: torch.Tensor,
                port_valid: torch.Tensor | None = None, evtol_valid: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Returns the latent ``(B, 4H)``, the port-node embeddings ``(B, P, H)``, the encoded
        port-node features ``(B, P, Fp')`` and the embedding of the extra vector ``(B, H)``.

        On a complete graph a GCN layer gives every node the same normalised sum of all nodes,
        so the node embeddings carry the graph's context, not the node's identity: what sets a
        node apart (its availability, type, position) comes from its encoded features."""
        evtol_x = self.evtol_enc(evtols)
        if self.acting_col is not None:  # the acting vehicle's index, as a flag on its node
            idx = torch.arange(evtols.shape[1], device=evtols.device, dtype=extra.dtype)
            acting = (idx.unsqueeze(0) == extra[:, self.acting_col:self.acting_col + 1]).to(evtol_x.dtype)
            evtol_x = torch.cat([evtol_x, acting.unsqueeze(-1)], dim=-1)
        port_x = self.port_enc(ports)
        port_nodes, port_pool = self.port_gcn(port_x, port_valid)
        evtol_nodes, evtol_pool = self.evtol_gcn(evtol_x, evtol_valid)
        is_self = evtols[..., self.is_self_col].unsqueeze(-1)  # (B, N, 1), one-hot over N
        self_node = (evtol_nodes * is_self).sum(dim=1)
        extra_emb = self.extra(self.extra_enc(extra))
        latent = torch.cat([port_pool, evtol_pool, self_node, extra_emb], dim=-1)
        return latent, port_nodes, port_x, extra_emb


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
                                    tuple(names["extra"]), self._hidden)
        return groups, self.encoder.out_dim

    def encode(self, obs: TensorDict) -> tuple[torch.Tensor, ...]:
        """The encoder's outputs (see GraphEncoder.forward)."""
        ports, evtols, extra = (obs[g] for g in self.obs_groups)
        keys = obs.keys()
        port_valid = obs["port_valid"].bool() if "port_valid" in keys else None
        evtol_valid = obs["evtol_valid"].bool() if "evtol_valid" in keys else None
        return self.encoder(ports.float(), evtols.float(), extra.float(), port_valid, evtol_valid)

    def get_latent(self, obs: TensorDict, masks=None, hidden_state=None) -> torch.Tensor:
        return self.encode(obs)[0]


def _last_linear(seq: nn.Sequential) -> nn.Linear:
    """The output layer of an MLP built as a ``Sequential`` ending in a linear layer."""
    last = seq[-1]
    if not isinstance(last, nn.Linear):
        raise TypeError(f"the MLP ends in {type(last).__name__}, not a linear layer")
    return last


class GraphActor(_GraphModel):
    """Shared GCN actor: legal-action-masked logits ``(B, 4 + P)`` -> :class:`MaskedCategorical`.

    The MLP head scores the four actions that name no node; a node scorer (an MLP with the same
    hidden widths) scores each node action from the node's GCN embedding, its own encoded
    features (availability, type, position), the embedding of the acting eVTOL's own feature
    vector and the node's position relative to the eVTOL (see the module docstring).

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
        dist_cfg["num_choices"] = FIXED_ACTIONS  # the head's width; node actions are appended
        super().__init__(obs, obs_groups, obs_set, output_dim, feature_names, hidden, hidden_dims,
                         dist_cfg)
        if not isinstance(self.distribution, MaskedCategorical):
            raise TypeError("GraphActor needs a MaskedCategorical-compatible distribution, got "
                            f"{type(self.distribution).__name__}")
        extra = list(feature_names["extra"])
        self.self_xy_cols = [extra.index("x_m"), extra.index("y_m")]
        layers: list[nn.Module] = []
        width = 2 * hidden + self.encoder.port_enc.out_dim + _RELATIVE
        for h in hidden_dims:
            layers += [nn.Linear(width, h), nn.RReLU(0.1, 0.3)]
            width = h
        layers.append(nn.Linear(width, 1))
        self.node_scorer = nn.Sequential(*layers)
        self.train(self.training)

    def logits(self, obs: TensorDict) -> torch.Tensor:
        """Unmasked logits ``(B, 4 + P)``: stay, take off, the P node actions, continue, avoid."""
        latent, port_nodes, port_x, own_emb = self.encode(obs)
        fixed = self.mlp(latent)  # (B, FIXED_ACTIONS)
        ports = obs[self.obs_groups[0]].float()
        own = obs[self.obs_groups[2]].float()
        scale = FEATURE_SCALES["x_m"]
        rel = (ports[..., self.encoder.port_xy_cols] - own[:, self.self_xy_cols].unsqueeze(1)) / scale
        dist = rel.norm(dim=-1, keepdim=True)
        p = port_nodes.shape[1]
        pair = torch.cat([port_nodes, port_x, own_emb.unsqueeze(1).expand(-1, p, -1), rel, dist], dim=-1)
        nodes = self.node_scorer(pair).squeeze(-1)  # (B, P)
        return torch.cat([fixed[:, :LEADING_ACTIONS], nodes, fixed[:, LEADING_ACTIONS:]], dim=-1)

    @torch.no_grad()
    def sharpen(self, temperature: float) -> None:
        """Divide every logit by ``temperature`` for good, by scaling the weights and biases of
        the two output layers (the head's and the node scorer's, both linear), so the argmax,
        the greedy action, is unchanged; below 1 the policy samples closer to it."""
        if not (temperature > 0 and math.isfinite(temperature)):
            raise ValueError(f"temperature must be a finite number > 0, got {temperature}")
        for layer in (_last_linear(self.mlp), _last_linear(self.node_scorer)):
            layer.weight.div_(temperature)
            layer.bias.div_(temperature)

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
