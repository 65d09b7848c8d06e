"""rsl_rl ``VecEnv`` adapters over ``K`` copies of the vertiport, for the two training modes.

Observation groups (a flat TensorDict with a leading row dimension):

- ``port_nodes (R, P, 4)``, ``evtol_nodes (R, N, 13)``, ``self (R, 11)``, ``action_mask (R, A)``
  bool: the observation of the eVTOL a row acts for;
- multi-agent mode only: ``state_port_nodes (R, P, 5)``, ``state_evtol_nodes (R, N, 17)``,
  ``state_clock (R, 3)``: the global ``state()`` with ``is_self`` marking the row's eVTOL, for
  the centralised critic; ``port_valid (R, P)`` and ``evtol_valid (R, N)`` bool mark the real
  nodes when the copies run different vertiports (below).

**Scenarios** (multi-agent mode): the copies may run a list of env configs (copy ``k`` runs
config ``k mod len(configs)``) with different layouts and fleets. Every copy's graphs are then
padded to the largest ``P`` and ``N`` of the list and its action space to ``A = 4 + P``
(agents/gcn/padding.py); a copy with fewer eVTOLs has rows that never act (only "stay" legal).

**Lost-vehicle penalty** (``lost_vehicle_penalty``, both modes): the reward the learner sees is
the paper's reward minus the penalty for each vehicle lost in the step (stranded in the air or
on the ground, the step's ``info["vehicles_lost"]``): a documented training term; the episode
metrics keep the paper's reward.

**Multi-agent** (:class:`MultiAgentVecEnv`, CTDE): the PettingZoo AEC env, stepped here directly,
in process (supersuit's vector wrappers need parallel envs with every agent acting each step).
Each step every copy advances one AEC step, in which the eVTOL whose turn it is acts on its own
observation with the shared actor. Two row layouts:

- ``rows="agents"``: one row per (copy, eVTOL), ``R = K * N``. The other rows of a copy get a
  mask with only "stay" legal and their action is ignored (probability 1, so no policy
  gradient). By default every row of a copy gets the reward of the step (the team reward: the
  eVTOLs cooperate toward the fleet's total, as the ATC does); with ``team_reward=False`` only
  the acting row gets it, so each row's return is that eVTOL's own reward stream.
- ``rows="turns"``: one row per copy, ``R = K``, holding the observation of the eVTOL whose turn
  it is: the AEC game's turns as one stream, each with the step's (team) reward. With the team
  reward this is the ``agents`` layout without its rows that cannot act: the same advantages at
  the acting rows, for ``1 / N`` of the model's work.

The critic reads ``critic="state"``: the global ``state()`` (the centralised critic), or
``critic="observation"``: the observation of the row's eVTOL (independent critics with shared
weights). With ``"observation"`` the state groups are not built at all, so nothing of the
state can reach a model.

**Unresolved-conflict penalty** (``conflict_penalty``, both modes): subtracted from the learner's
reward in a step whose acting eVTOL was in a predicted conflict and did not avoid it (the
paper's ``S = -5``, which the evaluation counts as a collision): a documented training term.

**Reward scale** (``reward_scale``, both modes): the learner's reward (after the penalties) is
multiplied by it, so that returns and values are of order one; metrics keep the
paper's reward.

**Single agent** (:class:`SingleAgentVecEnv`, fully centralised): the Gymnasium env vectorised
with supersuit (``gym_vec_env_v0``; with ``multiprocessing=True`` each copy runs in its own
worker process), one row per copy, ``R = K``; scenarios with the same spaces (``paper`` and
``paper_uncertain``) are cycled over the copies with Gymnasium's vector envs; actor and critic both see the acting
eVTOL's (centralised) observation. Gymnasium's vector envs reset a finished copy on the step
after its truncation, so one transition in 1440 per copy carries no reward.

Both report truncations as ``extras["time_outs"]`` (with ``dones``) and, when episodes end, their
metrics in ``extras["episode"]``. Buffers are allocated once; every step returns fresh tensors
(rsl_rl keeps a reference to the observation it acted on).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from agents.gcn.padding import from_padded_action, pad_action_mask, to_tensordict
from agents.common.seeds import training_seed
from marl_vertiport.config import EnvConfig, load_config
from marl_vertiport.sim.schema import EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES, ActionLayout
from marl_vertiport.spaces import ObservationBuilder
from marl_vertiport.sim.metrics import TRAINING_METRICS

#: The multi-agent row layouts and what its critic may read (the train config's ``rows`` and
#: ``critic``).
ROW_LAYOUTS = ("agents", "turns")
CRITIC_INPUTS = ("state", "observation")

#: Episode metrics logged by rsl_rl (averaged over the episodes that end in an iteration).
LOGGED_METRICS = TRAINING_METRICS


def _load_configs(config: str | EnvConfig | list, owner: str) -> list[EnvConfig]:
    """An env config, or a list of them (scenarios), loaded; an empty list is refused."""
    configs = [load_config(c) for c in (config if isinstance(config, (list, tuple)) else [config])]
    if not configs:
        raise ValueError(f"{owner} needs at least one env config")
    return configs


class _VertiportVecEnv(VecEnv):
    """What both adapters share: config, row bookkeeping, action conversion, episode extras."""

    def __init__(self, config: str | EnvConfig, num_envs: int, rows_per_env: int,
                 device: str = "cpu", seed: int = 0, lost_vehicle_penalty: float = 0.0,
                 reward_scale: float = 1.0, conflict_penalty: float = 0.0) -> None:
        if not (reward_scale > 0 and np.isfinite(reward_scale)):
            raise ValueError(f"reward_scale must be a finite number > 0, got {reward_scale}")
        self.env_config = load_config(config)
        self.lost_vehicle_penalty = float(lost_vehicle_penalty)
        self.conflict_penalty = float(conflict_penalty)
        self.reward_scale = float(reward_scale)
        self.num_copies = int(num_envs)
        self.rows_per_env = rows_per_env
        self.num_envs = self.num_copies * rows_per_env
        self.num_actions = 1
        self.max_episode_length = self.env_config.schedule.episode_steps
        self.device = torch.device(device)
        self.cfg = {"env_config": self.env_config.name, "num_copies": self.num_copies}
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)
        self._seed = seed
        self._episodes_started = 0
        self._finished: list[dict[str, Any]] = []

    def pop_episode_means(self) -> dict[str, float]:
        """Mean metrics of the episodes finished since the last call (empty if none)."""
        if not self._finished:
            return {}
        means = {k: float(np.mean([float(m[k]) for m in self._finished])) for k in LOGGED_METRICS}
        self._finished = []
        return means

    def acting_rows(self) -> torch.Tensor:
        """Rows whose action takes effect at the next step."""
        return torch.arange(self.num_envs)

    def _next_seed(self) -> int:
        seed = training_seed(self._seed * 100_003 + self._episodes_started)
        self._episodes_started += 1
        return seed

    def _to_int_actions(self, actions: torch.Tensor) -> np.ndarray:
        return actions.detach().reshape(-1).round().long().cpu().numpy()

    def _episode_extras(self, finished: list[dict[str, Any]]) -> dict[str, torch.Tensor]:
        self._finished.extend(finished)
        return {key: torch.tensor([float(m[key]) for m in finished]) for key in LOGGED_METRICS}

    def _tensors(self, arrays: dict[str, np.ndarray]) -> TensorDict:
        return to_tensordict(arrays, self.num_envs, self.device)


class MultiAgentVecEnv(_VertiportVecEnv):
    """One row per (env copy, eVTOL); see the module docstring.

    Args:
        config: the env config, or a list of them (scenarios, cycled over the copies).
        rows: ``"agents"`` (a row per copy and eVTOL) or ``"turns"`` (a row per copy: the eVTOL
            whose turn it is).
        critic: what the critic's groups hold: ``"state"`` (the global state) or
            ``"observation"`` (none: the critic reads the row's observation groups).
    """

    ROWS = ROW_LAYOUTS
    CRITICS = CRITIC_INPUTS

    def __init__(self, config: str | EnvConfig | list = "paper", num_envs: int = 8,
                 device: str = "cpu", seed: int = 0, team_reward: bool = True,
                 lost_vehicle_penalty: float = 0.0, rows: str = "agents",
                 critic: str = "state", reward_scale: float = 1.0,
                 conflict_penalty: float = 0.0) -> None:
        from marl_vertiport.vertiport_v1 import raw_env

        if rows not in self.ROWS:
            raise ValueError(f"rows must be one of {self.ROWS}, got {rows!r}")
        if critic not in self.CRITICS:
            raise ValueError(f"critic must be one of {self.CRITICS}, got {critic!r}")
        if rows == "turns" and not team_reward:
            raise ValueError("rows='turns' holds one stream of turns per copy, which has only "
                             "the team reward: team_reward=False needs rows='agents'")
        configs = _load_configs(config, "MultiAgentVecEnv")
        max_n = max(c.fleet_size for c in configs)
        self.turn_rows = rows == "turns"
        self.with_state = critic == "state"
        super().__init__(configs[0], num_envs, 1 if self.turn_rows else max_n, device, seed,
                         lost_vehicle_penalty, reward_scale, conflict_penalty)
        self.scenarios = configs
        self.cfg["env_config"] = [c.name for c in configs]
        self.cfg.update(rows=rows, critic=critic)
        self.team_reward = team_reward
        self.envs = [raw_env(config=configs[k % len(configs)]) for k in range(self.num_copies)]
        for env in self.envs:
            env.reset(seed=self._next_seed())
        sims = [env.sim for env in self.envs]
        self.padded = len({(sim.n, sim.layout.n_nodes) for sim in sims}) > 1
        n, p = max_n, max(sim.layout.n_nodes for sim in sims)
        self.max_nodes, self.max_evtols = p, n
        a = ActionLayout(p).n
        k, r = self.num_copies, self.rows_per_env
        self._buf = {
            "port_nodes": np.zeros((k, r, p, len(PORT_FEATURES)), np.float32),
            "evtol_nodes": np.zeros((k, r, n, len(EVTOL_FEATURES)), np.float32),
            "self": np.zeros((k, r, len(SELF_FEATURES)), np.float32),
            "action_mask": np.zeros((k, r, a), np.int8),
        }
        if self.with_state:
            st = self.envs[0].state()
            self._buf.update({
                "state_port_nodes": np.zeros((k, r, p, st["port_nodes"].shape[-1]), np.float32),
                "state_evtol_nodes": np.zeros((k, r, n, st["evtol_nodes"].shape[-1]), np.float32),
                "state_clock": np.zeros((k, r) + st["clock"].shape, np.float32),
            })
        if self.padded:
            self._buf["port_valid"] = np.zeros((k, r, p), bool)
            self._buf["evtol_valid"] = np.zeros((k, r, n), bool)
            for c, sim in enumerate(sims):
                self._buf["port_valid"][c, :, : sim.layout.n_nodes] = True
                self._buf["evtol_valid"][c, :, : sim.n] = True
        self._noop_mask = np.zeros(a, np.int8)
        self._noop_mask[sims[0].actions.stay] = 1
        self.builders = [ObservationBuilder(sim) for sim in sims]
        self._turn_observer = np.zeros(1, np.intp)
        self._agent_observers = [np.where(np.arange(r) < sim.n, np.arange(r), -1) for sim in sims]
        self._obs = self._observe_all()

    def _observe_copy(self, k: int) -> None:
        """Copy ``k``'s rows: through the env's observation builder (the one path from the
        simulator to what a policy reads), padded rows left as they are."""
        buf, builder = self._buf, self.builders[k]
        sim = builder.sim
        p, v = sim.layout.n_nodes, sim.acting
        # Per row, the eVTOL it observes for; the rows of a copy's absent eVTOLs (-1) get the
        # graphs alone.
        observers = self._turn_observer if self.turn_rows else self._agent_observers[k]
        if self.turn_rows:
            observers[0] = v
        builder.observe_into(observers, buf["port_nodes"][k], buf["evtol_nodes"][k], buf["self"][k])
        mask = pad_action_mask(sim.action_mask(v), p, self.max_nodes)
        if self.turn_rows:  # the one row is the acting eVTOL's
            buf["action_mask"][k, 0] = mask
        else:
            masks = buf["action_mask"][k]
            masks[:] = self._noop_mask
            masks[v] = mask
        if self.with_state:
            builder.state_into(observers, buf["state_port_nodes"][k], buf["state_evtol_nodes"][k],
                               buf["state_clock"][k])

    def _observe_all(self) -> TensorDict:
        for k in range(self.num_copies):
            self._observe_copy(k)
        flat = {key: v.reshape((self.num_envs,) + v.shape[2:]) for key, v in self._buf.items()}
        return self._tensors(flat)

    def get_observations(self) -> TensorDict:
        return self._obs.clone()

    def acting_rows(self) -> torch.Tensor:
        if self.turn_rows:
            return torch.arange(self.num_envs)
        return torch.tensor([k * self.rows_per_env + env.sim.acting for k, env in enumerate(self.envs)])

    def step(self, actions: torch.Tensor):
        acts = self._to_int_actions(actions).reshape(self.num_copies, self.rows_per_env)
        rewards = np.zeros((self.num_copies, self.rows_per_env), np.float32)
        dones = np.zeros_like(rewards, dtype=bool)
        finished = []
        for k, env in enumerate(self.envs):
            sim = env.sim
            v = sim.acting
            row = 0 if self.turn_rows else v
            env.step(from_padded_action(int(acts[k, row]), sim.layout.n_nodes, self.max_nodes))
            agent = env.possible_agents[v]
            info = env.infos[agent]
            reward = env.rewards[agent] - self.lost_vehicle_penalty * info["vehicles_lost"]
            if info["reward_terms"]["safety"] < 0:
                reward -= self.conflict_penalty
            reward *= self.reward_scale
            if self.team_reward:
                rewards[k] = reward  # every eVTOL of the copy shares the fleet's reward
            else:
                rewards[k, v] = reward
            if sim.truncated:
                finished.append(sim.episode_metrics())
                dones[k] = True
                env.reset(seed=self._next_seed())
        dones_t = torch.from_numpy(dones.reshape(-1)).to(self.device)
        self.episode_length_buf += 1
        self.episode_length_buf[dones_t] = 0
        self._obs = self._observe_all()
        extras: dict[str, Any] = {"time_outs": dones_t.clone()}
        if finished:
            extras["episode"] = self._episode_extras(finished)
        return (self._obs.clone(), torch.from_numpy(rewards.reshape(-1)).to(self.device),
                dones_t.long(), extras)

    def close(self) -> None:
        for env in self.envs:
            env.close()


class SingleAgentVecEnv(_VertiportVecEnv):
    """One row per env copy, vectorised with supersuit; see the module docstring.

    Args:
        config: the env config, or a list of them (scenarios, cycled over the copies: copy
            ``k`` runs config ``k mod len(configs)``). The single agent's observation and
            action spaces have no padding, so every config of a list must have the same
            spaces (the same vertiport and fleet, as ``paper`` and ``paper_uncertain``).
    """

    def __init__(self, config: str | EnvConfig | list = "paper", num_envs: int = 8,
                 device: str = "cpu", seed: int = 0, multiprocessing: bool = False,
                 lost_vehicle_penalty: float = 0.0, reward_scale: float = 1.0,
                 conflict_penalty: float = 0.0) -> None:
        import gymnasium
        import supersuit as ss

        from marl_vertiport.gym_env import VertiportEnv

        configs = _load_configs(config, "SingleAgentVecEnv")
        super().__init__(configs[0], num_envs, 1, device, seed, lost_vehicle_penalty, reward_scale,
                         conflict_penalty)
        self.scenarios = configs
        self.cfg["env_config"] = [c.name for c in configs]
        # multiprocessing: one worker process per copy (gymnasium's AsyncVectorEnv with shared
        # memory; supersuit's concat_vec_envs cannot concatenate nested Dict observations).
        if len(configs) == 1:
            self.venv = ss.gym_vec_env_v0(VertiportEnv(config=configs[0]), self.num_copies,
                                          multiprocessing=multiprocessing)
        else:
            envs = [VertiportEnv(config=c) for c in configs]
            for env, c in zip(envs[1:], configs[1:]):
                if (env.observation_space != envs[0].observation_space
                        or env.action_space != envs[0].action_space):
                    raise ValueError(
                        f"single-agent scenarios must share their observation and action spaces "
                        f"(the same vertiport and fleet): {c.name!r} differs from "
                        f"{configs[0].name!r}; train across layouts with mode multi_agent")
            for env in envs:
                env.close()
            fns = [lambda c=configs[k % len(configs)]: VertiportEnv(config=c)
                   for k in range(self.num_copies)]
            vector = gymnasium.vector.AsyncVectorEnv if multiprocessing else gymnasium.vector.SyncVectorEnv
            self.venv = vector(fns)
        obs, _ = self.venv.reset(seed=self._next_seed())
        self._obs = self._convert(obs)

    def _convert(self, obs: dict) -> TensorDict:
        inner = obs["observation"]
        return self._tensors({"port_nodes": inner["port_nodes"], "evtol_nodes": inner["evtol_nodes"],
                              "self": inner["self"], "action_mask": obs["action_mask"]})

    def get_observations(self) -> TensorDict:
        return self._obs.clone()

    def step(self, actions: torch.Tensor):
        obs, rewards, terminated, truncated, info = self.venv.step(self._to_int_actions(actions))
        done = np.logical_or(terminated, truncated)
        dones_t = torch.from_numpy(done).to(self.device)
        self.episode_length_buf += 1
        self.episode_length_buf[dones_t] = 0
        self._obs = self._convert(obs)
        rewards = np.asarray(rewards, dtype=np.float32)
        if self.lost_vehicle_penalty:
            lost = np.asarray(info.get("vehicles_lost", np.zeros(len(done))), dtype=np.float32)
            rewards = rewards - self.lost_vehicle_penalty * lost
        if self.conflict_penalty and "reward_terms" in info:  # absent in a step of resets
            safety = np.asarray(info["reward_terms"]["safety"], dtype=np.float32)
            rewards = rewards - self.conflict_penalty * (safety < 0)
        if self.reward_scale != 1.0:
            rewards = rewards * self.reward_scale
        extras: dict[str, Any] = {"time_outs": torch.from_numpy(np.asarray(truncated)).to(self.device)}
        if done.any() and "episode" in info:
            ep = info["episode"]
            rows = np.flatnonzero(done)
            extras["episode"] = self._episode_extras(
                [{k: np.asarray(ep[k])[r] for k in LOGGED_METRICS} for r in rows])
        return (self._obs.clone(), torch.as_tensor(rewards, dtype=torch.float32, device=self.device),
                dones_t.long(), extras)

    def close(self) -> None:
        self.venv.close()

