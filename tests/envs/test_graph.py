"""Graph helpers: batched conversion equals PyG's own collation, and a GCN sees the same."""

import numpy as np
import pytest
import torch
from torch_geometric.data import Batch, Data
from torch_geometric.nn import GCNConv, global_mean_pool

from marl_vertiport import vertiport_v1
from marl_vertiport.graph import to_graph_batch, to_state_batch


def collect(n: int, seed: int = 0) -> list[dict]:
    env = vertiport_v1.env(config="paper_uncertain")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        obs = env.observe(env.agent_selection)
        out.append(obs)
        env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    return out, env


def complete_edges(n: int) -> torch.Tensor:
    """Every ordered pair of distinct nodes, written out by hand (both graphs are complete)."""
    pairs = [(i, j) for i in range(n) for j in range(n) if i != j]
    return torch.tensor(pairs, dtype=torch.long).T


def reference(obs_list, nodes_key) -> Batch:
    return Batch.from_data_list([
        Data(x=torch.as_tensor(o["observation"][nodes_key]).float(),
             edge_index=complete_edges(len(o["observation"][nodes_key])))
        for o in obs_list])


def test_list_conversion_equals_pyg_collation():
    obs_list, _ = collect(37)
    g = to_graph_batch(obs_list)
    for ours, key in ((g.ports, "port"), (g.evtols, "evtol")):
        ref = reference(obs_list, f"{key}_nodes")
        assert torch.equal(ours.x, ref.x)
        assert torch.equal(ours.edge_index, ref.edge_index)
        assert torch.equal(ours.batch, ref.batch)
        assert ours.num_graphs == ref.num_graphs == 37
    assert g.self_features.shape == (37, 11)
    assert g.action_mask.dtype == torch.bool and g.action_mask.shape == (37, 14)


def test_batched_arrays_tensors_and_single_agree():
    obs_list, _ = collect(5)
    stacked = {"observation": {k: np.stack([o["observation"][k] for o in obs_list])
                               for k in obs_list[0]["observation"]},
               "action_mask": np.stack([o["action_mask"] for o in obs_list])}
    as_tensors = {"observation": {k: torch.as_tensor(v) for k, v in stacked["observation"].items()},
                  "action_mask": torch.as_tensor(stacked["action_mask"])}
    a, b, c = to_graph_batch(obs_list), to_graph_batch(stacked), to_graph_batch(as_tensors)
    for other in (b, c):
        assert torch.equal(a.ports.x, other.ports.x)
        assert torch.equal(a.evtols.edge_index, other.evtols.edge_index)
        assert torch.equal(a.action_mask, other.action_mask)
    single = to_graph_batch(obs_list[3])
    assert single.num_graphs == 1
    assert torch.equal(single.evtols.x, a.evtols.x[4 * 3:4 * 4])


def test_gcn_on_the_batch_equals_per_graph():
    torch.manual_seed(0)
    obs_list, _ = collect(6)
    g = to_graph_batch(obs_list)
    conv = GCNConv(13, 16)
    pooled = global_mean_pool(conv(g.evtols.x, g.evtols.edge_index), g.evtols.batch)
    for i, o in enumerate(obs_list):
        x = torch.as_tensor(o["observation"]["evtol_nodes"]).float()
        ei = complete_edges(len(x))
        torch.testing.assert_close(pooled[i], conv(x, ei).mean(0))


def test_state_conversion():
    _, env = collect(3)
    ports, evtols, clock = to_state_batch([env.state(), env.state()])
    assert ports.num_graphs == 2 and evtols.x.shape == (8, 17) and clock.shape == (2, 3)


def test_bad_input_is_named():
    with pytest.raises(KeyError, match="evtol_nodes"):
        to_graph_batch({"observation": {"port_nodes": np.zeros((3, 4))}})
    with pytest.raises(ValueError, match="empty"):
        to_graph_batch([])
