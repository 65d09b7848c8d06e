"""The vertiport AEC env in TorchRL: ``PettingZooWrapper``, a masked actor, a critic that can
read ``state()``, and a reference PPO loop. Needs the torchrl extra (``pip install -e '.[torchrl]'``).

What TorchRL needs from the env, and where it finds it:

* ``use_mask=True`` (compulsory for an AEC env): ``("evtol", "mask")`` marks the one agent that
  acts on each step; the others' actions are ignored by the env and must be left out of the
  loss (here through ``ClipPPOLoss.loss_mask_key``).
* ``observation["action_mask"]`` (int8) becomes the bool ``("evtol", "action_mask")``; the
  actor hands it to ``MaskedCategorical``, so an illegal action is never sampled (the env
  would raise ``ValueError``). The non-acting agents' rows are all ones.
* ``return_state=True`` reads ``env.state_space`` and puts ``env.state()`` at ``"state"``
  (``clock``, ``evtol_nodes``, ``port_nodes``) on every step: :func:`make_critic` gives it
  to a centralised critic, one value per agent.
* All agents share one group (``group_map={"evtol": [...]}``), so one network acts for the
  whole fleet; the graph observation arrives nested at ``("evtol", "observation",
  "observation", key)``.

The Parallel env (``vertiport_v1.parallel_env``, one parallel step per ATC turn) goes in the
same wrapper the way BenchMARL's PettingZoo tasks build theirs (:func:`make_parallel_env`:
``use_mask`` off, every agent submits an action each step, the agents whose turn it is not
with the no-op alone in their ``action_mask``); with ``flat=True`` the observation is the flat
``Box`` of :mod:`marl_vertiport.flat` at ``("evtol", "observation")``, the one tensor
BenchMARL's models read. :func:`ppo` then takes every agent's row into the loss (MAPPO-style):
a row whose mask leaves one action has a log-probability of 0 and adds nothing to the
objective, only to the critic.

A minimal run (one torch thread: several times faster than torch's default on these small
batches, docs/ecosystem.md)::

    import torch
    torch.set_num_threads(1)
    from agents.interop.torchrl_env import make_env, make_actor, make_critic, ppo

    env = make_env("paper", seed=0, **{"schedule.episode_steps": 64})
    actor, critic = make_actor(env), make_critic(env)
    for stats in ppo(env, actor, critic, iterations=3, frames_per_batch=64):
        print(stats)
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from typing import Any

import torch
from torch import nn

from agents.interop import require
from agents.common.nets import mlp, symlog
from marl_vertiport import vertiport_v1

__all__ = ["ACTING", "ACTION", "ACTION_MASK", "GROUP", "LOG_PROB", "OBSERVATION", "VALUE",
           "make_actor", "make_critic", "make_env", "make_parallel_env", "ppo"]

EXTRA = "torchrl"
require("torchrl", EXTRA)  # fail at import, with the install command, without the extra

GROUP = "evtol"
#: The graph observation's keys sit under this one (PettingZoo's "observation" key, nested in
#: the wrapper's own "observation" once "action_mask" has moved up).
OBSERVATION = (GROUP, "observation", "observation")
ACTION_MASK = (GROUP, "action_mask")      # bool (..., n_agents, n_actions)
ACTING = (GROUP, "mask")                  # bool (..., n_agents): who acts on this step
ACTION = (GROUP, "action")
LOGITS = (GROUP, "logits")
LOG_PROB = (GROUP, "action_log_prob")
VALUE = (GROUP, "state_value")
REWARD = (GROUP, "reward")


def make_env(config: Any = "paper", *, seed: int | None = None, return_state: bool = True,
             **overrides: Any):
    """The AEC env (``vertiport_v1.env``) behind TorchRL's ``PettingZooWrapper``, all agents in
    the group ``"evtol"``; ``overrides`` as in ``vertiport_v1.env``."""
    from torchrl.envs import PettingZooWrapper

    aec = vertiport_v1.env(config=config, **overrides)
    with warnings.catch_warnings():  # TorchRL's notice that it was tested with another PettingZoo
        warnings.filterwarnings("ignore", message="PettingZoo in TorchRL is tested")
        return PettingZooWrapper(env=aec, use_mask=True, categorical_actions=True,
                                 return_state=return_state, seed=seed,
                                 group_map={GROUP: list(aec.possible_agents)})


def make_parallel_env(config: Any = "paper", *, seed: int | None = None,
                      return_state: bool = True, flat: bool = False, **overrides: Any):
    """The Parallel env (``vertiport_v1.parallel_env``) behind TorchRL's ``PettingZooWrapper``
    as a BenchMARL PettingZoo task builds it (``categorical_actions=True``, ``use_mask`` off,
    ``return_state``), all agents in the group ``"evtol"``; ``flat=True`` wraps it in
    :class:`marl_vertiport.flat.FlatParallel` first (one observation tensor per agent)."""
    from torchrl.envs import PettingZooWrapper

    from marl_vertiport.flat import FlatParallel

    par = vertiport_v1.parallel_env(config=config, **overrides)
    if flat:
        par = FlatParallel(par)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="PettingZoo in TorchRL is tested")
        return PettingZooWrapper(env=par, categorical_actions=True, return_state=return_state,
                                 seed=seed, device="cpu",
                                 group_map={GROUP: list(par.possible_agents)})


def _observation_key(env) -> tuple:
    """Where the group's observation sits: nested graphs (:data:`OBSERVATION`) or one tensor
    (``("evtol", "observation")``, the flat observation)."""
    spec = env.observation_spec[GROUP, "observation"]
    return OBSERVATION if hasattr(spec, "keys") else (GROUP, "observation")


class _Flatten(nn.Module):
    """The inputs' last ``event_dims[i]`` dimensions raveled and joined, then symlog."""

    def __init__(self, event_dims: tuple[int, ...]) -> None:
        super().__init__()
        self.event_dims = event_dims

    def forward(self, *xs: torch.Tensor) -> torch.Tensor:
        return symlog(torch.cat([x.flatten(x.ndim - d) if d > 1 else x
                                 for x, d in zip(xs, self.event_dims)], dim=-1))


def _group_keys(spec, prefix: tuple, batch_dims: int) -> tuple[list, tuple[int, ...], int]:
    """The leaf keys under ``prefix`` of an observation spec, their event dimensions (beyond
    ``batch_dims``) and their total size."""
    sub = spec[prefix]
    if not hasattr(sub, "keys"):  # one tensor (the flat observation)
        shape = sub.shape[batch_dims:]
        return [prefix], (max(len(shape), 1),), int(torch.Size(shape).numel())
    keys, dims, size = [], [], 0
    for key in sub.keys():
        shape = sub[key].shape[batch_dims:]
        keys.append((*prefix, key))
        dims.append(max(len(shape), 1))
        size += int(torch.Size(shape).numel())
    return keys, tuple(dims), size


class _ActorNet(nn.Module):
    def __init__(self, event_dims: tuple[int, ...], n_in: int, n_actions: int, hidden: int):
        super().__init__()
        self.flat, self.mlp = _Flatten(event_dims), mlp(n_in, n_actions, hidden)

    def forward(self, *xs: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.flat(*xs))


def make_actor(env, hidden: int = 64):
    """One shared MLP over each agent's flattened graph observation, sampling from a
    ``MaskedCategorical`` of its logits and ``("evtol", "action_mask")``."""
    from tensordict.nn import TensorDictModule
    from torchrl.modules import MaskedCategorical, ProbabilisticActor

    n_agents = env.full_action_spec[ACTION].shape[-1]
    n_actions = env.full_action_spec[ACTION].space.n
    keys, dims, size = _group_keys(env.observation_spec, _observation_key(env), 1)
    net = TensorDictModule(_ActorNet(dims, size, n_actions, hidden), in_keys=keys,
                           out_keys=[LOGITS])
    assert env.observation_spec[ACTION_MASK].shape == (n_agents, n_actions)
    return ProbabilisticActor(net, in_keys={"logits": LOGITS, "mask": ACTION_MASK},
                              out_keys=[ACTION], distribution_class=MaskedCategorical,
                              return_log_prob=True, log_prob_key=LOG_PROB)


class _CentralCritic(nn.Module):
    """V(state, agent): the flattened global state with a one-hot of each agent, one value
    per agent of the group."""

    def __init__(self, event_dims: tuple[int, ...], n_in: int, n_agents: int, hidden: int):
        super().__init__()
        self.n_agents = n_agents
        self.flat, self.mlp = _Flatten(event_dims), mlp(n_in + n_agents, 1, hidden)

    def forward(self, *xs: torch.Tensor) -> torch.Tensor:
        state = self.flat(*xs)                                       # (..., S)
        lead = state.shape[:-1]
        per_agent = state.unsqueeze(-2).expand(*lead, self.n_agents, state.shape[-1])
        who = torch.eye(self.n_agents, dtype=state.dtype, device=state.device)
        return self.mlp(torch.cat([per_agent, who.expand(*lead, -1, -1)], dim=-1))


def make_critic(env, hidden: int = 64, centralised: bool | None = None):
    """A value per agent at ``("evtol", "state_value")``: centralised (from ``"state"``, the
    env's ``state()``) when the env was made with ``return_state=True``, otherwise from the
    agent's own observation."""
    from tensordict.nn import TensorDictModule

    has_state = "state" in env.observation_spec.keys()
    centralised = has_state if centralised is None else centralised
    if centralised and not has_state:
        raise ValueError("a centralised critic reads state(): make the env with return_state=True")
    if centralised:
        n_agents = env.full_action_spec[ACTION].shape[-1]
        keys, dims, size = _group_keys(env.observation_spec, ("state",), 0)
        module = _CentralCritic(dims, size, n_agents, hidden)
    else:
        keys, dims, size = _group_keys(env.observation_spec, _observation_key(env), 1)
        module = _ActorNet(dims, size, 1, hidden)
    return TensorDictModule(module, in_keys=keys, out_keys=[VALUE])


def ppo(env, actor, critic, *, iterations: int = 3, frames_per_batch: int = 64,
        epochs: int = 4, minibatch_size: int = 32, lr: float = 3e-4, gamma: float = 0.99,
        lmbda: float = 0.95, clip_epsilon: float = 0.2, entropy_coeff: float = 0.01,
        seed: int = 0) -> Iterator[dict[str, float]]:
    """TorchRL's PPO on the env: a ``Collector`` gathers ``frames_per_batch`` steps, GAE
    (per agent, over every step) gives the advantages, and ``ClipPPOLoss`` is minimised over
    the acting agents' rows only on the AEC env (``use_mask``), over every agent's row on the
    Parallel env. Yields one dict per iteration: the steps collected, the acting agents' steps
    (one a step) and illegal actions among every submitted action, the episodes ended, the
    summed reward and the last minibatch's losses."""
    from torchrl.collectors import Collector
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    torch.manual_seed(seed)
    loss = ClipPPOLoss(actor, critic, clip_epsilon=clip_epsilon, entropy_coeff=entropy_coeff,
                       normalize_advantage=False)
    loss.set_keys(action=ACTION, sample_log_prob=LOG_PROB, value=VALUE, reward=REWARD,
                  done=(GROUP, "done"), terminated=(GROUP, "terminated"))
    aec = bool(getattr(env, "use_mask", False))
    if aec:
        loss.loss_mask_key = ACTING  # only the agent that acted on a step has a loss there
    loss.make_value_estimator(ValueEstimators.GAE, gamma=gamma, lmbda=lmbda)
    optim = torch.optim.Adam(loss.parameters(), lr=lr)
    collector = Collector(env, actor, frames_per_batch=frames_per_batch,
                          total_frames=frames_per_batch * iterations,
                          auto_register_policy_transforms=False)
    try:
        for it, data in enumerate(collector):
            chosen = data[ACTION_MASK].gather(-1, data[ACTION].unsqueeze(-1)).squeeze(-1)
            # The Parallel env: every agent submits an action, and every one must be legal.
            acting = data[ACTING] if aec else torch.ones_like(chosen)
            with torch.no_grad():
                loss.value_estimator(data, params=loss.critic_network_params,
                                     target_params=loss.target_critic_network_params)
            steps = data.shape[0]
            last: dict[str, float] = {}  # the losses of the last minibatch
            for _ in range(epochs):
                for idx in torch.randperm(steps).split(minibatch_size):
                    out = loss(data[idx])
                    total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
                    optim.zero_grad()
                    total.backward()
                    nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
                    optim.step()
                    for key in ("loss_objective", "loss_critic", "loss_entropy"):
                        last[key] = float(out[key].detach())
            collector.update_policy_weights_()
            yield {"iteration": it, "frames": steps,
                   "acting_steps": int(data[ACTING].sum()) if aec else steps,
                   "illegal_actions": int((acting & ~chosen).sum()),
                   "episodes_ended": int(data["next", "done"].sum()),
                   "reward": float(data["next", *REWARD][acting].sum()),
                   **last}
    finally:
        collector.shutdown()
