"""Helpers the tests of several layers share (``from helpers import ...``: pytest puts ``tests/``
on the import path): a policy that keeps the fleet busy, so long runs exercise flight,
charging, landing and conflicts rather than a fleet parked with empty batteries; the paper's
simulator in a known first state; a tiny train config."""

import numpy as np

from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT, SELF_FEATURES, ActionLayout
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT

STAY, TAKEOFF = ActionLayout.stay, ActionLayout.takeoff


def busy_action(obs: dict, rng: np.random.Generator) -> int:
    """A legal action from the observation alone: charge when low, take off near the
    scheduled time, land hovering vehicles, and otherwise pick a random legal action."""
    mask = obs["action_mask"]
    legal = np.flatnonzero(mask)
    own = obs["observation"]["self"]
    ports = obs["observation"]["port_nodes"]
    status, battery = int(own[0]), own[1]
    minutes_to_schedule = own[SELF_FEATURES.index("minutes_to_schedule")]
    node_actions = ActionLayout(len(ports)).node_action(np.arange(len(ports)))
    movable = mask[node_actions] == 1  # free, and within the battery under the energy check
    free_chargers = node_actions[movable & (ports[:, 1] == CHARGING_PORT)]
    free_ports = node_actions[movable & (ports[:, 1] != HOVER_SPOT)]
    if rng.random() < 0.02:
        return int(rng.choice(legal))
    if status in (ON_PORT, ON_CHARGER):
        if battery > 60 and minutes_to_schedule <= 3 and mask[TAKEOFF]:
            return TAKEOFF
        if status == ON_PORT and battery < 90 and free_chargers.size:
            return int(free_chargers[0])
        return STAY
    if status == HOVERING:
        choice = free_chargers if free_chargers.size else free_ports
        return int(choice[0]) if choice.size else STAY
    return int(legal[0]) if legal.size == 1 else len(mask) - 2  # continue in transit


def seed0_sim(rules: int = 0, **overrides):
    """The paper config after ``reset(default_rng(0))``, whose placement the hand-computed tests
    rely on: evtol_0 on the charging port (node 2), evtol_1 on normal port 1, evtol_2 on normal
    port 0, evtol_3 at hover spot 7; take-offs at minutes 16, 15, 13, evtol_3's landing at 15.

    Under the rules v0 by default: the hand-built situations of the paper's mechanics (reward
    terms, schedule, battery, energy check) move vehicles by hand, which the separation check of
    v1 would refuse or which leave its reservations stale; tests/sim/test_clearance.py builds
    the situations of v1."""
    from marl_vertiport.config import load_config, with_rules
    from marl_vertiport.sim.core import VertiportSim

    sim = VertiportSim(with_rules(load_config("paper", **overrides), rules))
    sim.reset(np.random.default_rng(0))
    assert sim.status.tolist() == [ON_CHARGER, ON_PORT, ON_PORT, HOVERING]
    assert sim.node.tolist() == [2, 1, 0, 7]
    assert sim.pending_time.tolist() == [16, 15, 13, 15]
    return sim


def tiny_config(mode: str, **extra):
    """A train config of a few PPO steps and no warm start, no evaluation; ``extra`` keys
    replace the defaults."""
    from agents.training.config import TrainConfig
    from marl_vertiport.config import build_dataclass, to_dict

    base = to_dict(TrainConfig())
    base.update(mode=mode, num_envs=2, num_steps_per_env=8, iterations=2, save_interval=1,
                critic_warmup_iterations=0,
                pretrain={"days": 0, "epochs": 0, "batch_size": 64, "learning_rate": 1e-3},
                evaluation={"episodes": 0, "agents": []})
    base.update(extra)
    return build_dataclass(TrainConfig, base)


def small_actor(hidden: int = 16, hidden_dims: tuple[int, ...] = (32,)):
    """A small GCN actor of the paper's vertiport, shaped by an observation of its env."""
    from agents.controllers.gcn import GCNController
    from agents.gcn.features import feature_names
    from agents.gcn.models import GraphActor
    from marl_vertiport.config import load_config
    from marl_vertiport.vertiport_v1 import raw_env

    probe = raw_env(config=load_config("paper"))
    probe.reset(seed=0)
    example = GCNController._tensors(probe.observe("evtol_0"))
    probe.close()
    return GraphActor(example, {"actor": ["port_nodes", "evtol_nodes", "self"]}, "actor", 1,
                      feature_names("observation"), hidden=hidden, hidden_dims=list(hidden_dims))


class FixedAction:
    """A controller that always takes ``action``."""

    def __init__(self, action: int) -> None:
        self.action = action

    def act(self, observation: dict) -> int:
        return self.action


def dispatcher_decision(env, found, seeds=(0,)):
    """The first decision at which ``found(sim, obs, legal, choice)`` holds, on days ``seeds``
    (in order) of the AEC ``env`` flown by the dispatcher, with the day played up to it:
    (the dispatcher, bound to the simulator; that decision's observation; the dispatcher's
    choice; the legal actions, a list)."""
    from agents.controllers.dispatcher import DispatcherController

    for seed in seeds:
        env.reset(seed=seed)
        sim = env.unwrapped.sim
        dispatcher = DispatcherController()
        dispatcher.bind(sim)
        for agent in env.agent_iter():
            if env.terminations[agent] or env.truncations[agent]:
                env.step(None)
                continue
            obs = env.observe(agent)
            legal = np.flatnonzero(obs["action_mask"]).tolist()
            choice = dispatcher.act(obs)
            if found(sim, obs, legal, choice):
                return dispatcher, obs, choice, legal
            env.step(choice)
    raise AssertionError(f"no such decision on days {list(seeds)} flown by the dispatcher")


def guarded_actions(env, guard, seed: int) -> list[int]:
    """The actions a look-ahead ``guard`` takes on day ``seed`` of ``env``, bound to its simulator."""
    actions = []
    env.reset(seed=seed)
    guard.reset(seed=seed)
    guard.bind(env.unwrapped.sim)
    for agent in env.agent_iter():
        if env.terminations[agent] or env.truncations[agent]:
            env.step(None)
            continue
        actions.append(guard.act(env.observe(agent)))
        env.step(actions[-1])
    return actions
