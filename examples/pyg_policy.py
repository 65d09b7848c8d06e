"""A torch-geometric policy on the env's graphs: GCN layers of your own over the complete graphs
that ``marl_vertiport.graph.to_graph_batch`` builds, acting for every eVTOL in turn.

    python examples/pyg_policy.py [DAYS]

The weights here are untrained (a seeded initialisation), so the point is the plumbing: one
batch per decision, a score per action, illegal actions masked. Train such a model with your own
loop, or see agents/gcn/ for the shipped policy and its rsl_rl training.
"""

import sys
from pathlib import Path

import torch
from torch import nn
from torch_geometric.nn import GCNConv, global_mean_pool

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # so `agents` imports

from agents.controllers.episode import run_aec_episode  # noqa: E402
from marl_vertiport import vertiport_v1  # noqa: E402
from marl_vertiport.graph import to_graph_batch  # noqa: E402
from marl_vertiport.sim.schema import (  # noqa: E402
    EVTOL_FEATURES, LEADING_ACTIONS, PORT_FEATURES, SELF_FEATURES, TRAILING_ACTIONS,
)


class PygPolicy(nn.Module):
    """Two GCN layers per graph, mean-pooled, joined with the acting eVTOL's features; the
    actions that name no node are scored from that, each node action from its node's
    embedding and the same context. Any layout and fleet size."""

    def __init__(self, hidden: int = 32, seed: int = 0) -> None:
        super().__init__()
        torch.manual_seed(seed)
        self.port_convs = nn.ModuleList([GCNConv(len(PORT_FEATURES), hidden), GCNConv(hidden, hidden)])
        self.evtol_convs = nn.ModuleList([GCNConv(len(EVTOL_FEATURES), hidden), GCNConv(hidden, hidden)])
        context = 2 * hidden + len(SELF_FEATURES)
        self.fixed_head = nn.Linear(context, LEADING_ACTIONS + TRAILING_ACTIONS)
        self.node_head = nn.Linear(hidden + context, 1)

    @staticmethod
    def _encode(graph, convs) -> torch.Tensor:
        x = graph.x
        for conv in convs:
            x = torch.relu(conv(x, graph.edge_index))
        return x

    def forward(self, observation: dict) -> torch.Tensor:
        """Masked logits ``(B, A)`` of a batch of observations."""
        g = to_graph_batch(observation)
        ports = self._encode(g.ports, self.port_convs)                       # (B*P, H)
        evtols = self._encode(g.evtols, self.evtol_convs)                    # (B*N, H)
        context = torch.cat([global_mean_pool(ports, g.ports.batch),
                             global_mean_pool(evtols, g.evtols.batch), g.self_features], dim=-1)
        b = g.num_graphs
        nodes = ports.view(b, -1, ports.shape[-1])                           # (B, P, H)
        pair = torch.cat([nodes, context.unsqueeze(1).expand(-1, nodes.shape[1], -1)], dim=-1)
        fixed = self.fixed_head(context)
        logits = torch.cat([fixed[:, :LEADING_ACTIONS], self.node_head(pair).squeeze(-1),
                            fixed[:, LEADING_ACTIONS:]], dim=-1)
        return logits.masked_fill(~g.action_mask, float("-inf"))


class PygController:
    """The policy as a controller: ``act(observation)`` takes the best legal action."""

    name = "pyg"

    def __init__(self) -> None:
        self.model = PygPolicy().eval()

    def act(self, observation: dict) -> int:
        with torch.no_grad():
            return int(self.model(observation).argmax(dim=-1).item())


if __name__ == "__main__":
    # One torch thread: on batches this small, torch's default (a thread per core) is several
    # times slower on a busy machine (experiments/torch-threads-small-batches).
    torch.set_num_threads(1)
    days = int(sys.argv[1]) if len(sys.argv) > 1 else 1
    for config in ("paper", "mid"):  # one set of weights, two vertiports
        env = vertiport_v1.env(config=config)
        for seed in range(days):
            m = run_aec_episode(env, PygController(), seed=seed)
            print(f"{config}, seed {seed}: {m['steps']} legal decisions, total reward "
                  f"{m['total_reward']:.0f}, vehicles lost {m['stranded']}")
        env.close()
