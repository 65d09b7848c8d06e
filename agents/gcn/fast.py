"""The GCN actor's forward pass for one observation in NumPy: the same logits as
:class:`agents.gcn.models.GraphActor` at a tenth of torch's per-call overhead (about 0.1 ms
against 1.4 ms on one core). The greedy GCN controller plays it (an evaluation's day, a
look-ahead's rollouts that call the policy at every simulated turn); training, sampling and
batches stay with torch.

Why it can be short: both graphs of an observation are complete, and a dense GCN layer with
self-loops on a complete graph of ``K`` nodes gives every node the same output,
``mean_k(x_k) W + b`` (each row of ``D^-1/2 (A + I) D^-1/2`` is ``1/K`` everywhere). So each
GCN branch is the mean of the encoded node features through two linear layers, the pooled
embedding and every node's embedding are that one vector, and the acting eVTOL's node
embedding is it too. What sets the node actions apart is each node's encoded features and its
position relative to the eVTOL, as in the torch model.

The arithmetic is float32, as torch's; the sums run in another order, so logits agree to about
1e-5 (tested) and the greedy action differs only where two legal actions tie that closely.
"""

from __future__ import annotations

import numpy as np
from torch import nn

from agents.gcn.models import FEATURE_SCALES, GraphActor, _GraphModel
from marl_vertiport.sim.schema import LEADING_ACTIONS

#: The slope of RReLU(0.1, 0.3) in the models: its mean, fixed in training and evaluation
#: alike (``_GraphModel.train``).
RRELU_SLOPE = np.float32(0.2)


def _rrelu(x: np.ndarray) -> np.ndarray:
    # max(x, 0.2 x) is x where x >= 0 and 0.2 x below: the fixed slope is under 1.
    return np.maximum(x, x * RRELU_SLOPE)


def _mlp_layers(seq: nn.Sequential) -> list[tuple[np.ndarray, np.ndarray]]:
    """The linear layers of an MLP of linear layers and RReLUs (the last one has no
    activation) as ``(W^T, b)`` float32 pairs."""
    layers = []
    for module in seq:
        if isinstance(module, nn.Linear):
            layers.append((module.weight.detach().numpy().T.astype(np.float32).copy(),
                           module.bias.detach().numpy().astype(np.float32).copy()))
        elif not isinstance(module, nn.RReLU):
            raise TypeError(f"unexpected layer {type(module).__name__} in the MLP")
    return layers


def _run_mlp(layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
    for i, (w, b) in enumerate(layers):
        x = x @ w + b
        if i < len(layers) - 1:
            x = _rrelu(x)
    return x


class _Encoder:
    """A :class:`~agents.gcn.models.FeatureEncoder`: scaled numeric columns, then one-hots."""

    def __init__(self, encoder) -> None:
        self.numeric = encoder.numeric_idx.numpy().copy()
        self.inv_scales = (1.0 / encoder.scales.numpy()).astype(np.float32)
        self.categorical = [(col, k, np.eye(k, dtype=np.float32)) for col, k in encoder.categorical]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        parts = [x[..., self.numeric] * self.inv_scales]
        for col, k, one_hot in self.categorical:
            idx = np.minimum(np.maximum(x[..., col].astype(np.int64), 0), k - 1)
            parts.append(one_hot[idx])
        return np.concatenate(parts, axis=-1)


class _Branch:
    """A :class:`~agents.gcn.models.GraphGCN` on a complete graph: ``(K, F) -> (H,)``, the one
    embedding every node (and the pool) gets."""

    def __init__(self, gcn) -> None:
        self.w1 = gcn.conv1.lin.weight.detach().numpy().T.astype(np.float32).copy()
        self.b1 = gcn.conv1.bias.detach().numpy().astype(np.float32).copy()
        self.w2 = gcn.conv2.lin.weight.detach().numpy().T.astype(np.float32).copy()
        self.b2 = gcn.conv2.bias.detach().numpy().astype(np.float32).copy()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        h = _rrelu(x.sum(axis=0) * np.float32(1.0 / x.shape[0]) @ self.w1 + self.b1)
        return _rrelu(h @ self.w2 + self.b2)


class FastGraphActor:
    """A copy of a :class:`~agents.gcn.models.GraphActor`'s weights that scores one observation
    in NumPy. Later changes to the torch actor's weights are not seen: build a new one.

    Args:
        actor: the torch actor (in evaluation, as a controller holds it).
    """

    def __init__(self, actor: GraphActor) -> None:
        if not isinstance(actor, _GraphModel):
            raise TypeError(f"FastGraphActor copies a GraphActor, got {type(actor).__name__}")
        enc = actor.encoder
        self.acting_col = enc.acting_col
        self.is_self_col = enc.is_self_col
        self.port_xy = list(enc.port_xy_cols)
        self.self_xy = list(actor.self_xy_cols)
        self.port_enc = _Encoder(enc.port_enc)
        self.evtol_enc = _Encoder(enc.evtol_enc)
        self.extra_enc = _Encoder(enc.extra_enc)
        self.port_gcn = _Branch(enc.port_gcn)
        self.evtol_gcn = _Branch(enc.evtol_gcn)
        (w_x, b_x), = _mlp_layers(enc.extra)
        self.extra_w, self.extra_b = w_x, b_x
        self.head = _mlp_layers(actor.mlp)
        scorer = _mlp_layers(actor.node_scorer)
        # The scorer's first layer on [node embedding, node features, own embedding, relative
        # position, distance], split by part: the embeddings are the same for every node.
        w0, b0 = scorer[0]
        hidden = self.port_gcn.b2.shape[0]
        fp = self.port_enc.inv_scales.shape[0] + sum(k for _, k, _ in self.port_enc.categorical)
        self.score_shared_w = np.concatenate([w0[:hidden], w0[hidden + fp: 2 * hidden + fp]])
        self.score_node_w = np.concatenate([w0[hidden: hidden + fp], w0[2 * hidden + fp:]])
        self.score_b0 = b0
        self.scorer_rest = scorer[1:]
        self.inv_xy_scale = np.float32(1.0 / FEATURE_SCALES["x_m"])

    def logits(self, observation: dict) -> np.ndarray:
        """Unmasked logits ``(4 + P,)`` of one AEC observation (``{"observation": ...}``)."""
        inner = observation["observation"]
        ports = np.asarray(inner["port_nodes"], dtype=np.float32)
        evtols = np.asarray(inner["evtol_nodes"], dtype=np.float32)
        own = np.asarray(inner["self"], dtype=np.float32)
        port_x = self.port_enc(ports)
        evtol_x = self.evtol_enc(evtols)
        if self.acting_col is not None:
            acting = (np.arange(evtols.shape[0]) == own[self.acting_col]).astype(np.float32)
            evtol_x = np.concatenate([evtol_x, acting[:, None]], axis=-1)
        port_emb = self.port_gcn(port_x)
        evtol_emb = self.evtol_gcn(evtol_x)
        self_emb = evtol_emb * evtols[:, self.is_self_col].sum()
        own_emb = _rrelu(self.extra_enc(own) @ self.extra_w + self.extra_b)
        fixed = _run_mlp(self.head, np.concatenate([port_emb, evtol_emb, self_emb, own_emb]))
        rel = (ports[:, self.port_xy] - own[self.self_xy]) * self.inv_xy_scale
        dist = np.sqrt((rel * rel).sum(axis=-1, keepdims=True))
        shared = np.concatenate([port_emb, own_emb]) @ self.score_shared_w + self.score_b0
        first = np.concatenate([port_x, rel, dist], axis=-1) @ self.score_node_w + shared
        if self.scorer_rest:  # a hidden layer: its activation, then the rest of the scorer
            nodes = _run_mlp(self.scorer_rest, _rrelu(first))[:, 0]
        else:
            nodes = first[:, 0]
        return np.concatenate([fixed[:LEADING_ACTIONS], nodes, fixed[LEADING_ACTIONS:]])

    def act(self, observation: dict) -> int:
        """The legal action with the largest logit (the first of equal ones, as torch's
        argmax)."""
        logits = self.logits(observation)
        mask = np.asarray(observation["action_mask"]).astype(bool)
        return int(np.argmax(np.where(mask, logits, -np.inf)))
