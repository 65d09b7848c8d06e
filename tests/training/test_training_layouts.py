"""The multi-agent training layouts: rows per turn (the acting eVTOL of each copy) against
rows per eVTOL, the reward scale, and the independent critics that read only the observation
groups (no ``state()``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS
from agents.training.config import TrainConfig
from agents.training.runner import runner_config
from agents.training.vec_env import MultiAgentVecEnv
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict, with_rules

ROOT = Path(__file__).resolve().parents[2]


def _actions_of(env: MultiAgentVecEnv, rng: np.random.Generator) -> torch.Tensor:
    obs = env.get_observations()
    legal = [np.flatnonzero(m) for m in obs["action_mask"].numpy()]
    return torch.tensor([[float(rng.choice(a))] for a in legal])


def test_turn_rows_hold_the_acting_evtols_observation_and_state_and_the_step_reward():
    env = MultiAgentVecEnv("paper", num_envs=2, seed=3, rows="turns", reward_scale=0.5)
    rng = np.random.default_rng(0)
    assert env.num_envs == 2
    for _ in range(60):
        obs = env.get_observations()
        for k, copy in enumerate(env.envs):
            agent = copy.agent_selection
            seen = copy.observe(agent)
            assert torch.equal(obs["port_nodes"][k], torch.from_numpy(seen["observation"]["port_nodes"]))
            assert torch.equal(obs["evtol_nodes"][k], torch.from_numpy(seen["observation"]["evtol_nodes"]))
            assert torch.equal(obs["self"][k], torch.from_numpy(seen["observation"]["self"]))
            assert torch.equal(obs["action_mask"][k], torch.from_numpy(seen["action_mask"]).bool())
            state = copy.state()
            for group in ("port_nodes", "evtol_nodes", "clock"):
                assert torch.equal(obs[f"state_{group}"][k], torch.from_numpy(state[group]))
        actions = _actions_of(env, rng)
        acting = [copy.agent_selection for copy in env.envs]
        _, rewards, _, _ = env.step(actions)
        for k, copy in enumerate(env.envs):
            assert copy.infos[acting[k]]["action"] == int(actions[k])
            assert float(rewards[k]) == pytest.approx(0.5 * copy.rewards[acting[k]])
    env.close()


def test_turn_rows_are_the_acting_rows_of_the_agent_rows():
    """Driven by the same actions, the two layouts play the same days; the turn rows are the
    agent rows of the acting eVTOLs, with the same rewards."""
    turns = MultiAgentVecEnv("paper", num_envs=3, seed=7, rows="turns")
    agents = MultiAgentVecEnv("paper", num_envs=3, seed=7, rows="agents")
    rng = np.random.default_rng(1)
    for _ in range(200):
        a_obs = agents.get_observations()
        t_obs = turns.get_observations()
        rows = agents.acting_rows()
        for key in t_obs.keys():
            assert torch.equal(t_obs[key], a_obs[key][rows]), key
        actions = _actions_of(turns, rng)
        full = torch.zeros(agents.num_envs, 1)
        full[rows] = actions
        _, t_rew, t_done, _ = turns.step(actions)
        _, a_rew, a_done, _ = agents.step(full)
        assert torch.equal(t_rew, a_rew[rows]) and torch.equal(t_done, a_done[rows])
    turns.close()
    agents.close()


def test_independent_critics_read_no_state_group():
    """critic: observation builds the critic on the observation groups alone, and the vec env
    builds no state group at all; a critic that read one would change with it."""
    from rsl_rl.runners import OnPolicyRunner

    base = to_dict(TrainConfig())
    base.update(mode="multi_agent", rows="turns", critic="observation", num_envs=2,
                num_steps_per_env=4, iterations=1, pretrain={"days": 0},
                evaluation={"episodes": 0, "agents": []})
    cfg = build_dataclass(TrainConfig, base)
    rc = runner_config(cfg)
    assert rc["obs_groups"]["critic"] == list(POLICY_GROUPS)
    assert rc["critic"]["feature_names"]["evtols"] == rc["actor"]["feature_names"]["evtols"]
    env = MultiAgentVecEnv("paper", num_envs=2, seed=0, rows="turns", critic="observation")
    obs = env.get_observations()
    assert not any(key.startswith("state_") for key in obs.keys())
    runner = OnPolicyRunner(env, rc, log_dir=None, device="cpu")
    critic = runner.alg.critic
    assert not set(critic.obs_groups) & set(STATE_GROUPS)
    values = critic(obs)
    # The same observation with state groups added (garbage): the critic's values do not move.
    garbage = {g: torch.full((2,) + s, float("nan")) for g, s in
               (("state_port_nodes", (10, 5)), ("state_evtol_nodes", (4, 17)), ("state_clock", (3,)))}
    with_state = TensorDict({**{k: obs[k] for k in obs.keys()}, **garbage}, batch_size=[2])
    assert torch.equal(critic(with_state), values)
    # The centralised critic does read them.
    central = runner_config(build_dataclass(TrainConfig, {**base, "critic": "state"}))
    assert central["obs_groups"]["critic"] == list(STATE_GROUPS)
    env.close()


def test_layout_options_are_checked():
    base = to_dict(TrainConfig())
    with pytest.raises(ConfigError, match="rows"):
        build_dataclass(TrainConfig, {**base, "rows": "diagonal"})
    with pytest.raises(ConfigError, match="critic"):
        build_dataclass(TrainConfig, {**base, "critic": "oracle"})
    with pytest.raises(ConfigError, match="team_reward"):
        build_dataclass(TrainConfig, {**base, "rows": "turns", "team_reward": False})
    with pytest.raises(ConfigError, match="reward_scale"):
        build_dataclass(TrainConfig, {**base, "reward_scale": 0.0})
    with pytest.raises(ValueError, match="rows"):
        MultiAgentVecEnv("paper", num_envs=1, rows="diagonal")


@pytest.mark.parametrize("mode", ["multi_agent", "single_agent"])
def test_conflict_penalty_is_charged_exactly_on_unresolved_conflicts(mode):
    """The learner's reward differs from the paper's (scaled) by the penalty in the steps whose
    acting eVTOL left a predicted conflict unresolved (S = -5, which the day's ``collisions``
    metric counts), and nowhere else."""
    from agents.training.vec_env import SingleAgentVecEnv

    # Rules v0: the separation check of v1 leaves no predicted conflict to penalise.
    paper_v0 = with_rules(load_config("paper"), 0)

    def make(penalty):
        if mode == "multi_agent":
            return MultiAgentVecEnv(paper_v0, num_envs=2, seed=1, rows="turns", reward_scale=0.5,
                                    conflict_penalty=penalty)
        return SingleAgentVecEnv(paper_v0, num_envs=2, seed=1, reward_scale=0.5,
                                 conflict_penalty=penalty)

    plain, charged = make(0.0), make(10.0)
    rng = np.random.default_rng(0)
    charged_steps = 0
    for _ in range(1400):  # within the first day: no copy resets
        actions = _actions_of(charged, rng)
        _, r_plain, _, _ = plain.step(actions)
        _, r_charged, _, _ = charged.step(actions)
        diff = r_plain - r_charged
        assert torch.all((diff.abs() < 1e-5) | ((diff - 5.0).abs() < 1e-5)), diff
        charged_steps += int(((diff - 5.0).abs() < 1e-5).sum())
    sims = ([copy.sim for copy in charged.envs] if mode == "multi_agent"
            else [copy.sim for copy in charged.venv.envs])
    assert charged_steps == sum(sim.metrics.collisions for sim in sims) >= 1
    plain.close()
    charged.close()


def test_single_agent_copies_cycle_scenarios_with_the_same_spaces():
    """The single agent trains across scenarios of one vertiport and fleet (copy k runs config
    k mod len); configs whose spaces differ are refused, naming the one that differs."""
    from agents.training.vec_env import SingleAgentVecEnv

    env = SingleAgentVecEnv(["paper", "paper_uncertain"], num_envs=3, seed=2)
    assert [copy.config.name for copy in env.venv.envs] == ["paper", "paper_uncertain", "paper"]
    obs, rewards, dones, _ = env.step(_actions_of(env, np.random.default_rng(0)))
    assert obs["action_mask"].shape[0] == rewards.shape[0] == dones.shape[0] == 3
    env.close()
    with pytest.raises(ValueError, match="'small' differs from 'paper'"):
        SingleAgentVecEnv(["paper", "small"], num_envs=2)


def test_critic_ablation_configs_differ_from_scratch_only_in_what_they_ablate():
    """(b) and (c) of the centralised-critic study extend scratch_v0.yaml (``base:``) and change
    only the critic's input or the mode, so the three runs share every other setting;
    scratch.yaml is scratch_v0.yaml under rules v1."""
    from agents.training.config import MOVED_TRAIN_CONFIGS, load_train_config

    def load(name):
        return to_dict(load_train_config(ROOT / MOVED_TRAIN_CONFIGS[name]))

    scratch = load("scratch_v0")
    for name, changed in [("scratch_independent", {"critic": "observation"}),
                          ("scratch_single", {"mode": "single_agent"})]:
        cfg = load(name)
        assert {k: v for k, v in cfg.items() if cfg[k] != scratch[k]} == changed
    cfg = to_dict(load_train_config("scratch"))
    assert {k: v for k, v in cfg.items() if cfg[k] != scratch[k]} == {"rules": 1}


def test_every_train_config_loads_and_the_sharpened_stage_keeps_the_warm_start():
    """Every YAML file under configs/train/ (subfolders too) is a valid train config, and so is
    every config of rules v0 kept with its experiment, under its file or its old name; the
    default trains under rules v1 with one DAgger round and no ensemble; ensemble_v0.yaml (the
    default under rules v0) distils an ensemble of fits before PPO, single_fit.yaml is it
    without that stage, and ppo_stage/sharpened.yaml keeps single_fit's warm start (its PPO
    stage alone differs), as they were measured."""
    from agents.common.names import RenamedWarning
    from agents.training.config import MOVED_TRAIN_CONFIGS, TRAIN_CONFIG_DIR, load_train_config

    files = sorted(TRAIN_CONFIG_DIR.rglob("*.yaml"))
    assert [p.relative_to(TRAIN_CONFIG_DIR).as_posix() for p in files] == [
        "default.yaml", "expert_iteration.yaml", "expert_iteration_prior.yaml",
        "ppo_stage/long.yaml", "scratch.yaml"]
    for path in files:
        assert load_train_config(path).rules == 1  # configs/train/ runs under today's rules
    for name, path in MOVED_TRAIN_CONFIGS.items():
        assert (ROOT / path).is_file() and load_train_config(ROOT / path).rules == 0
        with pytest.warns(RenamedWarning, match="moved|is now"):
            import agents.common.names as names

            names._noted.clear()
            assert load_train_config(name) == load_train_config(ROOT / path)
    default = to_dict(load_train_config("default"))
    assert default["rules"] == 1 and default["ensemble"]["fits"] == 0
    assert default["pretrain"]["dagger_rounds"] == 1 and default["pretrain"]["teacher"] == "planner"

    def load(name):
        return to_dict(load_train_config(ROOT / MOVED_TRAIN_CONFIGS[name]))

    old, single, stage = load("ensemble_v0"), load("single_fit"), load("ppo_stage/sharpened")
    assert old["rules"] == 0 and old["ensemble"]["fits"] == 4 and single["ensemble"]["fits"] == 0
    assert {k: v for k, v in single.items() if v != old[k]} == {"ensemble": single["ensemble"]}
    for key in ("pretrain", "model", "scenarios", "seed", "lost_vehicle_penalty", "mode", "ensemble"):
        assert stage[key] == single[key], key
    assert stage["warm_start_temperature"] == 0.3 and default["warm_start_temperature"] == 1.0


def test_the_models_and_the_algorithm_are_named_in_the_train_config(tmp_path):
    """rsl_rl builds the classes the config names (``model.*_class``, ``algorithm.class_name``);
    a model of one's own plugs in by name, and the GCN controller refuses a checkpoint of an
    actor class it does not play, without importing it."""
    import torch

    from agents.controllers.gcn import CheckpointError, GCNController
    from agents.controllers.registry import SHIPPED_CHECKPOINT

    cfg = build_dataclass(TrainConfig, {**to_dict(TrainConfig()), "model": {
        "actor_class": "agents.gcn.models:GraphActor", "critic_class": "tests.my_models:Critic",
        "distribution_class": "agents.gcn.distribution:MaskedCategorical"}})
    rc = runner_config(cfg)
    assert rc["critic"]["class_name"] == "tests.my_models:Critic"
    assert rc["actor"]["class_name"] == "agents.gcn.models:GraphActor"
    assert rc["actor"]["distribution_cfg"]["class_name"] == "agents.gcn.distribution:MaskedCategorical"
    assert rc["algorithm"]["class_name"] == "agents.training.ppo:WarmupPPO"
    content = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    model = content["infos"]["marl_vertiport"]["train_config"]["model"]
    model["actor_class"] = "os:system"
    with pytest.raises(CheckpointError, match="trained with the actor class os:system"):
        GCNController(content)


def test_a_row_per_evtol_and_a_row_per_turn_give_one_ppo_gradient():
    """From the same rollout, the two layouts give PPO the same gradient, up to the actor's
    scale. A row whose eVTOL has no turn has one legal action ("stay"), so its log-probability
    and entropy are 0 and carry no gradient; under the team reward and the centralised critic
    its reward, value, return and advantage are those of its copy's acting row. So the critic's
    gradient is the same, and the actor's is the turn rows' over N (the fleet size; times the
    ratio of the two advantage normalisations, within a few per cent of 1), a scale Adam's step
    does not see. Checked in eval mode (the RReLUs' slopes fixed), on one full mini-batch,
    without the entropy bonus (0 at those rows, so it too scales by 1/N) and with no binding
    gradient clip: what is left between the layouts in a run is which rows share a
    mini-batch, and the clip, which a gradient N times smaller meets less often."""
    from rsl_rl.runners import OnPolicyRunner

    n_copies, n_steps = 3, 10
    base = to_dict(TrainConfig())
    base.update(mode="multi_agent", critic="state", team_reward=True, num_envs=n_copies,
                num_steps_per_env=n_steps, iterations=1, reward_scale=0.05, conflict_penalty=10.0,
                pretrain={"days": 0}, evaluation={"episodes": 0, "agents": []},
                algorithm={"num_learning_epochs": 1, "num_mini_batches": 1, "entropy_coef": 0.0,
                           "max_grad_norm": 1e9, "use_clipped_value_loss": False,
                           "schedule": "fixed"})
    envs, algs = {}, {}
    torch.manual_seed(0)
    for rows in ("agents", "turns"):
        cfg = build_dataclass(TrainConfig, {**base, "rows": rows})
        envs[rows] = MultiAgentVecEnv("paper", num_envs=n_copies, seed=5, rows=rows,
                                      reward_scale=0.05, conflict_penalty=10.0)
        algs[rows] = OnPolicyRunner(envs[rows], runner_config(cfg), log_dir=None, device="cpu").alg
    fleet = envs["agents"].rows_per_env
    assert fleet == 4 and envs["agents"].num_envs == fleet * n_copies
    a, t = algs["agents"], algs["turns"]
    t.actor.load_state_dict(a.actor.state_dict())
    t.critic.load_state_dict(a.critic.state_dict())
    for alg in (a, t):  # the RReLUs' slopes fixed (in train mode each pass draws its own)
        alg.eval_mode()
    for _ in range(n_steps):
        rows = envs["agents"].acting_rows()
        obs_a, obs_t = envs["agents"].get_observations(), envs["turns"].get_observations()
        actions = a.act(obs_a)
        # The rows without a turn: one legal action, log-probability and entropy exactly 0.
        idle = torch.ones(fleet * n_copies, dtype=torch.bool)
        idle[rows] = False
        assert torch.all(obs_a["action_mask"][idle].sum(-1) == 1)
        assert torch.all(a.transition.actions_log_prob[idle] == 0)
        assert torch.all(a.actor.output_entropy[idle] == 0)
        # Every row of a copy has its copy's value (the critic reads state()).
        values = a.transition.values.reshape(n_copies, fleet)
        torch.testing.assert_close(values, values[:, :1].expand(-1, fleet))
        # The turn layout acts with the acting rows' sampled actions.
        t.act(obs_t)
        t.transition.actions = actions[rows].clone()
        t.transition.actions_log_prob = t.actor.get_output_log_prob(t.transition.actions).detach()
        torch.testing.assert_close(t.transition.actions_log_prob, a.transition.actions_log_prob[rows])
        torch.testing.assert_close(t.transition.values, a.transition.values[rows])
        _, rew_t, done_t, extras_t = envs["turns"].step(actions[rows])
        _, rew_a, done_a, extras_a = envs["agents"].step(actions)
        assert torch.equal(rew_a.reshape(n_copies, fleet), rew_t[:, None].expand(-1, fleet))
        t.process_env_step(obs_t, rew_t, done_t, {"time_outs": extras_t["time_outs"]})
        a.process_env_step(obs_a, rew_a, done_a, {"time_outs": extras_a["time_outs"]})
    for rows, alg in algs.items():
        alg.compute_returns(envs[rows].get_observations())
    # Returns repeat over a copy's rows.
    returns = a.storage.returns.reshape(n_steps, n_copies, fleet)
    torch.testing.assert_close(returns, returns[..., :1].expand(-1, -1, fleet))
    torch.testing.assert_close(returns[..., 0], t.storage.returns.reshape(n_steps, n_copies))
    # One full-batch update from each; the gradients it leaves are those at the common start.
    start = [p.detach().clone() for p in a.actor.parameters()]
    for alg in (a, t):
        alg.update()
    grads = {f"{rows}/{part}": [p.grad.clone() for p in getattr(alg, part).parameters()]
             for rows, alg in algs.items() for part in ("actor", "critic")}
    assert any(g.abs().max() > 0 for g in grads["turns/actor"])
    for g_a, g_t in zip(grads["agents/critic"], grads["turns/critic"]):
        torch.testing.assert_close(g_a, g_t, rtol=1e-4, atol=1e-7)
    flat_a = torch.cat([g.flatten() for g in grads["agents/actor"]])
    flat_t = torch.cat([g.flatten() for g in grads["turns/actor"]])
    # The scale: N, times the ratio of the advantages' standard deviations over the N * M
    # rows (each copy's advantages repeated N times) and over the M turn rows.
    m = n_steps * n_copies
    expected = fleet * math.sqrt(fleet * (m - 1) / (fleet * m - 1))
    scale = float(flat_t @ flat_a / (flat_a @ flat_a))
    assert abs(scale / expected - 1) < 1e-4, (scale, expected)
    torch.testing.assert_close(flat_a * scale, flat_t, rtol=1e-4, atol=1e-7)
    # Adam's step does not see that scale: the actor's parameters move alike from the common
    # start (wherever the gradient is well above Adam's eps, 1e-8).
    moves = {rows: torch.cat([(p.detach() - s0).flatten() for p, s0 in
                              zip(alg.actor.parameters(), start)]) for rows, alg in algs.items()}
    clear = flat_t.abs() > 1e-4
    assert clear.sum() > 1000 and moves["turns"][clear].abs().min() > 0
    torch.testing.assert_close(moves["agents"][clear], moves["turns"][clear], rtol=1e-3, atol=0)
    for rows in envs:
        envs[rows].close()
