"""The learned ATC's parts: masked distribution, GCN models, VecEnv adapters, training runs,
checkpoints, and the parity of the multi-agent and single-agent paths."""

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from agents.gcn.distribution import MaskedCategorical
from agents.gcn.models import GraphActor, GraphCritic
from agents.controllers.registry import SHIPPED_CHECKPOINT
from agents.controllers.gcn import CheckpointError, GCNController
from agents.gcn.features import feature_names
from agents.training.callbacks import TrainingDiverged
from agents.training.checkpoints import latest_checkpoint
from agents.training.config import TrainConfig
from agents.training.curves import read_curves
from agents.training.pipeline import train
from agents.training.runner import runner_config
from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS
from agents.training.vec_env import MultiAgentVecEnv, SingleAgentVecEnv
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution
def test_masked_categorical_matches_torch_on_hand_made_logits():
    logits = torch.tensor([[1.0, 2.0, 0.5, -1.0], [0.0, 0.0, 3.0, 1.0]])
    mask = torch.tensor([[True, False, True, True], [False, True, True, False]])
    dist = MaskedCategorical(1, 4)
    dist.update(logits, mask)
    for row in range(2):
        legal = mask[row]
        ref = torch.distributions.Categorical(logits=logits[row][legal])
        torch.testing.assert_close(dist.probs[row][legal], ref.probs)
        assert (dist.probs[row][~legal] == 0).all()
        torch.testing.assert_close(dist.entropy[row], ref.entropy())
        legal_idx = torch.nonzero(legal).squeeze(-1)
        lp = dist.log_prob(legal_idx[:, None].float().T.reshape(-1, 1)[:1].expand(2, 1))
        assert torch.isfinite(lp).all()
        for k, action in enumerate(legal_idx.tolist()):
            actions = torch.full((2, 1), float(action))
            torch.testing.assert_close(dist.log_prob(actions)[row], ref.log_prob(torch.tensor(k)))
    # row 0: probabilities of the legal logits (1, 0.5, -1) after softmax
    expected = torch.softmax(torch.tensor([1.0, 0.5, -1.0]), 0)
    torch.testing.assert_close(dist.probs[0, [0, 2, 3]], expected)
    assert dist.kl_divergence(dist.params, dist.params).abs().max() < 1e-6


def test_masked_categorical_never_samples_a_masked_action():
    torch.manual_seed(0)
    dist = MaskedCategorical(1, 6)
    logits = torch.randn(512, 6) * 3
    mask = torch.rand(512, 6) > 0.5
    mask[:, 0] = True
    dist.update(logits, mask)
    for _ in range(20):
        a = dist.sample().long().squeeze(-1)
        assert mask[torch.arange(512), a].all()
    assert mask[torch.arange(512), dist.deterministic_output(logits, mask).long().squeeze(-1)].all()
    assert torch.isfinite(dist.entropy).all()


# ------------------------------------------------------------------ models
def example_obs(batch: int, seed: int = 0) -> TensorDict:
    env = MultiAgentVecEnv("paper", num_envs=batch, seed=seed)
    obs = env.get_observations()
    env.close()
    return obs


def test_actor_and_critic_shapes_on_batched_graphs():
    obs = example_obs(3)  # 3 copies x 4 eVTOLs = 12 rows
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    critic = GraphCritic(obs, {"critic": list(STATE_GROUPS)}, "critic", 1, feature_names("state"))
    assert actor(obs).shape == (12, 1) and actor(obs, stochastic_output=True).shape == (12, 1)
    assert actor.get_output_log_prob(actor(obs, stochastic_output=True)).shape == (12,)
    assert actor.output_entropy.shape == (12,)
    assert actor.action_probabilities(obs).shape == (12, 14)
    assert critic(obs).shape == (12, 1)


def test_sharpening_divides_every_logit_and_keeps_the_greedy_actions():
    torch.manual_seed(2)
    obs = example_obs(3)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    actor.eval()
    with torch.no_grad():
        before, greedy = actor.logits(obs), actor(obs)
        actor.action_probabilities(obs)
        entropy = actor.distribution.entropy.clone()
        actor.sharpen(0.25)
        torch.testing.assert_close(actor.logits(obs), before / 0.25)
        assert torch.equal(actor(obs), greedy)
        actor.action_probabilities(obs)
        assert (actor.distribution.entropy <= entropy + 1e-6).all()
        assert (actor.distribution.entropy < entropy).any()
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="temperature"):
            actor.sharpen(bad)


def test_gcn_output_is_invariant_to_the_order_of_the_fleet():
    torch.manual_seed(1)
    obs = example_obs(2)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    critic = GraphCritic(obs, {"critic": list(STATE_GROUPS)}, "critic", 1, feature_names("state"))
    perm = torch.tensor([2, 0, 3, 1])
    shuffled = obs.clone()
    shuffled["evtol_nodes"] = obs["evtol_nodes"][:, perm]
    shuffled["state_evtol_nodes"] = obs["state_evtol_nodes"][:, perm]
    with torch.no_grad():
        torch.testing.assert_close(actor.logits(shuffled), actor.logits(obs))
        torch.testing.assert_close(critic(shuffled), critic(obs))


def test_reordering_nodes_of_a_type_permutes_the_node_action_probabilities():
    """Hover spots (nodes 3-9 of the paper layout) listed in another order: the probability of
    "go to spot k" moves with spot k; the other actions keep theirs."""
    torch.manual_seed(2)
    obs = example_obs(2)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    perm = torch.tensor([0, 1, 2, 5, 9, 3, 8, 4, 7, 6])  # new node j is old node perm[j]
    cols = torch.cat([torch.tensor([0, 1]), perm + 2, torch.tensor([12, 13])])
    shuffled = obs.clone()
    shuffled["port_nodes"] = obs["port_nodes"][:, perm]
    shuffled["action_mask"] = obs["action_mask"][:, cols]
    # a hovering row makes the spots legal actions
    shuffled["action_mask"][:, 2:12] = True
    full = obs.clone()
    full["action_mask"][:, 2:12] = True
    with torch.no_grad():
        p = actor.action_probabilities(full)
        q = actor.action_probabilities(shuffled)
    torch.testing.assert_close(q, p[:, cols])
    assert not torch.allclose(p[:, 5], p[:, 6])  # the spots are told apart (by position)


def test_lost_vehicle_penalty_by_hand():
    """The learner's reward is the paper's reward less the penalty per vehicle lost in the
    step: evtol_2 at 0 % on a normal port is stranded in the first step."""
    cfg = load_config("paper", **{"atc.energy_check": False})
    rewards = []
    for penalty in (0.0, 40.0):
        env = MultiAgentVecEnv(cfg, num_envs=1, seed=0, lost_vehicle_penalty=penalty)
        sim = env.envs[0].sim
        on_port = [v for v in range(sim.n) if sim.status[v] == 0]
        sim.battery[on_port[-1]] = 0.0
        acting = int(env.acting_rows()[0])
        actions = torch.zeros(env.num_envs, 1)  # stay
        _, r, _, _ = env.step(actions)
        paper = env.envs[0].rewards[env.envs[0].possible_agents[acting]]
        assert int(sim.lost.sum()) == 1
        rewards.append((float(r[0]), paper))
        env.close()
    (r0, paper0), (r1, paper1) = rewards
    assert r0 == pytest.approx(paper0) and paper1 == pytest.approx(paper0)
    assert r1 == pytest.approx(paper0 - 40.0)


# ------------------------------------------------------------------ parity of the two paths
@pytest.mark.slow
def test_actor_probabilities_identical_through_aec_and_single_agent_paths():
    torch.manual_seed(0)
    ma = MultiAgentVecEnv("paper_uncertain", num_envs=1, seed=3)
    sa = SingleAgentVecEnv("paper_uncertain", num_envs=1, seed=3)
    obs_ma, obs_sa = ma.get_observations(), sa.get_observations()
    actor = GraphActor(obs_ma, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    actor.eval()
    for step in range(1440):
        row = int(ma.acting_rows()[0])
        with torch.no_grad():
            p_ma = actor.action_probabilities(obs_ma[row:row + 1])
            p_sa = actor.action_probabilities(obs_sa)
        assert torch.equal(p_ma, p_sa), f"probabilities differ at step {step}"
        action = torch.multinomial(p_sa, 1).float()
        rows = torch.zeros(ma.num_envs, 1)
        rows[row] = action
        obs_ma, r_ma, d_ma, _ = ma.step(rows)
        obs_sa, r_sa, d_sa, _ = sa.step(action)
        assert float(r_ma[row]) == float(r_sa[0])
    assert bool(d_sa[0]) and bool(d_ma.all())


def tiny_config(mode: str, **extra) -> TrainConfig:
    base = to_dict(TrainConfig())
    base.update(mode=mode, num_envs=2, num_steps_per_env=8, iterations=2, save_interval=1,
                critic_warmup_iterations=0,
                pretrain={"days": 0, "epochs": 0, "batch_size": 64, "learning_rate": 1e-3},
                evaluation={"episodes": 0, "agents": []})
    base.update(extra)
    return build_dataclass(TrainConfig, base)


def test_one_ppo_iteration_same_update_in_both_modes_on_the_same_observations():
    """With one eVTOL the multi-agent rows are the single-agent rows; fed the same observations
    (the critic on the same groups), one PPO iteration from the same seed updates the
    parameters identically."""
    from rsl_rl.runners import OnPolicyRunner

    params = []
    for mode, cls in (("multi_agent", MultiAgentVecEnv), ("single_agent", SingleAgentVecEnv)):
        cfg = tiny_config(mode, env_config="paper")
        env = cls(build_env_cfg(), num_envs=2, seed=5)
        rc = runner_config(cfg)
        rc["obs_groups"]["critic"] = list(POLICY_GROUPS)
        rc["critic"]["feature_names"] = feature_names("observation")
        torch.manual_seed(0)
        runner = OnPolicyRunner(env, rc, log_dir=None, device="cpu")
        runner.learn(1)
        params.append(torch.cat([p.detach().flatten() for p in runner.alg.actor.parameters()]
                                + [p.detach().flatten() for p in runner.alg.critic.parameters()]))
        env.close()
    assert torch.equal(params[0], params[1])


def build_env_cfg():
    return load_config("paper", fleet_size=1)


# ------------------------------------------------------------------ training runs
@pytest.mark.parametrize("mode", ["multi_agent", "single_agent"])
def test_two_iteration_training_save_reload_and_resume(tmp_path, mode):
    teacher = "rollout" if mode == "multi_agent" else "heuristic"
    cfg = tiny_config(mode, pretrain={"days": 2, "day_steps": 24, "teacher": teacher,
                                      "rollout_horizon": 4, "workers": 1, "epochs": 1,
                                      "batch_size": 64, "learning_rate": 1e-3, "dagger_rounds": 1})
    final = train(cfg, tmp_path, log=lambda *_: None, evaluate=False)
    assert final.name == "model_1.pt" and (tmp_path / "model_0.pt").exists()
    warm = torch.load(tmp_path / "model_warmstart.pt", weights_only=True)["infos"]["warm_start"]
    # Two fits (behaviour cloning, one DAgger round), each scored; the best one is kept.
    assert {"fit_0_score", "fit_1_score"} <= set(warm) and "fit_2_score" not in warm
    assert warm["chosen_fit"] == max((0, 1), key=lambda k: warm[f"fit_{k}_score"])
    assert (tmp_path / "curves.csv").exists() and (tmp_path / "learning_curves.png").exists()
    assert not list(tmp_path.glob("*.tmp"))
    ctl = GCNController(final)
    from agents.controllers.episode import run_aec_episode
    from marl_vertiport import vertiport_v0

    metrics = run_aec_episode(vertiport_v0.env(**{"schedule.episode_steps": 20}), ctl, 1)
    assert metrics["steps"] == 20
    # Resume to 3 iterations: continues from model_1 and writes model_2.
    cfg3 = build_dataclass(TrainConfig, {**to_dict(cfg), "iterations": 3})
    final3 = train(cfg3, tmp_path, resume=True, log=lambda *_: None, evaluate=False)
    assert final3.name == "model_2.pt"
    assert [int(r["iteration"]) for r in read_curves(tmp_path / "curves.csv")] == [0, 1, 2]


class _RunsCode:
    """Unpickling this object calls ``open(path, "w")``: a stand-in for a hostile file."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_bad_checkpoints_are_refused_clearly(tmp_path):
    bad = tmp_path / "model_3.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        GCNController(bad)
    marker = tmp_path / "ran"
    torch.save({"actor_state_dict": {}, "infos": _RunsCode(str(marker))}, tmp_path / "hostile.pt")
    with pytest.raises(CheckpointError, match="corrupt or not a torch file"):
        GCNController(tmp_path / "hostile.pt")
    assert not marker.exists()  # the file's pickled call was not made
    torch.save({"foo": 1}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not a marl_vertiport training checkpoint"):
        GCNController(tmp_path / "other.pt")
    # A checkpoint made with another observation schema is refused, both schemas named.
    small = tmp_path / "small.yaml"
    small.write_text("base: paper\nfleet_size: 3\n")
    final = train(tiny_config("single_agent", iterations=1, env_config=str(small)),
                  tmp_path / "small", log=lambda *_: None, evaluate=False)
    data = torch.load(final, weights_only=True)
    data["infos"]["marl_vertiport"]["feature_schema"]["ports"].append("altitude_m")
    torch.save(data, tmp_path / "other_schema.pt")
    with pytest.raises(CheckpointError, match="altitude_m"):
        GCNController(tmp_path / "other_schema.pt")


def test_checkpoint_of_one_layout_acts_legally_a_full_day_on_others(tmp_path):
    """Trained on the paper's ports with 3 eVTOLs, it flies a whole day on a 5-eVTOL layout
    with two chargers and on a 6-eVTOL layout with 14 nodes; every action it takes is legal
    (the env raises on an illegal one)."""
    from agents.controllers.episode import run_aec_episode
    from marl_vertiport import vertiport_v0

    small = tmp_path / "small.yaml"
    small.write_text("base: paper\nfleet_size: 3\n")
    final = train(tiny_config("multi_agent", iterations=1, env_config=str(small)),
                  tmp_path / "small", log=lambda *_: None, evaluate=False)
    ctl = GCNController(final)
    for config in ("mid", "twin"):
        metrics = run_aec_episode(vertiport_v0.env(config=config), ctl, 1_000_000)
        assert metrics["steps"] == 1440


def test_nan_in_training_stops_with_the_iteration_named(tmp_path, monkeypatch):
    from rsl_rl.algorithms import PPO

    original = PPO.update

    def poisoned(self):
        losses = original(self)
        losses["value"] = float("nan")
        return losses

    monkeypatch.setattr(PPO, "update", poisoned)
    with pytest.raises(TrainingDiverged, match="iteration 0"):
        train(tiny_config("single_agent"), tmp_path, log=lambda *_: None, evaluate=False)


@pytest.mark.slow
def test_killed_run_resumes_from_its_last_checkpoint(tmp_path):
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "agents.train", "--config", str(tmp_path / "cfg.yaml"),
           "--run-dir", str(run), "--no-eval"]
    import yaml

    cfg = to_dict(tiny_config("single_agent", iterations=200))
    (tmp_path / "cfg.yaml").write_text(yaml.safe_dump(cfg))
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    deadline = time.time() + 120
    while time.time() < deadline:  # wait for a checkpoint beyond the first
        last = latest_checkpoint(run)
        if last is not None and last.name != "model_0.pt":
            break
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    last = latest_checkpoint(run)
    assert last is not None
    done = int(last.stem.split("_")[1])
    torch.load(last, weights_only=True)  # the last checkpoint is complete and loads
    cfg_short = build_dataclass(TrainConfig, {**cfg, "iterations": done + 2})
    final = train(cfg_short, run, resume=True, log=lambda *_: None, evaluate=False)
    assert final.name == f"model_{done + 1}.pt"


def test_run_killed_during_the_warm_start_resumes_it(tmp_path, monkeypatch):
    """A run stopped after the warm start's first round goes on from its saved progress and
    ends with the same warm-started actor as a run never stopped."""
    import agents.training.imitation as imitation
    from agents.training.checkpoints import WARM_STATE

    cfg = tiny_config("single_agent", iterations=1,
                      pretrain={"days": 1, "day_steps": 24, "starts": 1, "start_steps": 12,
                                "low_battery_starts": 1, "noise": 0.2, "teacher": "heuristic",
                                "workers": 1, "epochs": 1, "batch_size": 64,
                                "learning_rate": 1e-3, "dagger_rounds": 1})
    train(cfg, tmp_path / "whole", log=lambda *_: None, evaluate=False)
    original = imitation.fit_actor
    calls = []

    def stop_at_second_fit(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(imitation, "fit_actor", stop_at_second_fit)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, tmp_path / "cut", log=lambda *_: None, evaluate=False)
    monkeypatch.setattr(imitation, "fit_actor", original)
    assert (tmp_path / "cut" / WARM_STATE).exists() and latest_checkpoint(tmp_path / "cut") is None
    assert len(read_curves(tmp_path / "cut" / "warmstart.csv")) == 1
    lines = []
    train(cfg, tmp_path / "cut", resume=True, log=lines.append, evaluate=False)
    assert any("resuming after round 0" in line for line in lines)
    whole = torch.load(tmp_path / "whole" / "model_warmstart.pt", weights_only=True)
    cut = torch.load(tmp_path / "cut" / "model_warmstart.pt", weights_only=True)
    assert whole["infos"]["warm_start"] == cut["infos"]["warm_start"]
    for key, value in whole["actor_state_dict"].items():
        assert torch.equal(value, cut["actor_state_dict"][key]), key
    rows = read_curves(tmp_path / "cut" / "warmstart.csv")
    assert [r["round"] for r in rows] == [0.0, 1.0, 2.0] and rows[0]["driver"] == 0.0
    assert rows[-1]["kept_round"] == whole["infos"]["warm_start"]["chosen_fit"] + 1
    np.testing.assert_equal(rows, read_curves(tmp_path / "whole" / "warmstart.csv"))  # NaN == NaN
    # Progress made with another configuration is refused, naming the file.
    other = build_dataclass(TrainConfig, {**to_dict(cfg), "seed": 5})
    with pytest.raises(ValueError, match="another configuration"):
        imitation.warm_start(None, other, to_dict(load_config("paper")), log=lambda *_: None,
                             state_path=tmp_path / "cut" / WARM_STATE)
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        train(cfg, tmp_path / "empty", resume=True, log=lambda *_: None, evaluate=False)
    (tmp_path / "cut" / WARM_STATE).write_bytes(b"junk")
    with pytest.raises(ValueError, match="not a readable warm-start state"):
        imitation.load_warm_start_state(tmp_path / "cut" / WARM_STATE)


def test_log_writer_passes_each_iteration_to_the_runs_callback(tmp_path):
    """rsl_rl's LogWriter extension point: the callback (handed over in the runner's config
    through store_config) sees an iteration as soon as its last always-logged scalar arrives,
    and whole (with Train/ scalars) once the next one starts."""
    from agents.training.callbacks import Callback
    from agents.training.log_writer import CALLBACK_KEY, RunLogWriter

    calls = []

    class Recorder(Callback):
        def on_iteration(self, it, scalars):
            calls.append(("updated", it, sorted(scalars)))

        def on_iteration_end(self, it, scalars):
            calls.append(("done", it, scalars.get("Train/mean_reward")))

    writer = RunLogWriter(str(tmp_path), tensorboard=False)
    writer.store_config({}, {"num_steps_per_env": 8, CALLBACK_KEY: Recorder()})
    for it, reward in ((0, None), (1, 12.5)):
        writer.add_scalar("Loss/value", 0.5, it)
        writer.add_scalar("Perf/learning_time", 0.1, it)
        if reward is not None:
            writer.add_scalar("Train/mean_reward", reward, it)
            writer.add_scalar("Train/mean_reward/time", reward, 37)  # indexed by seconds
    writer.stop()
    assert calls == [("updated", 0, ["Loss/value", "Perf/learning_time"]), ("done", 0, None),
                     ("updated", 1, ["Loss/value", "Perf/learning_time"]), ("done", 1, 12.5)]


def test_ppo_starts_from_the_warm_start_sharpened_by_the_temperature(tmp_path, monkeypatch):
    """``warm_start_temperature``: model_warmstart.pt keeps the imitation actor; PPO's first
    iteration (actor frozen) holds it with the two output layers divided by the temperature
    and every other weight unchanged."""
    import agents.training.pipeline as pipeline

    def fake_warm_start(actor, *args, **kwargs):
        with torch.no_grad():
            for p in actor.parameters():
                p.normal_()
        return {"chosen_fit": 0}

    monkeypatch.setattr(pipeline, "warm_start", fake_warm_start)
    cfg = tiny_config("multi_agent", iterations=1, critic_warmup_iterations=1,
                      warm_start_temperature=0.5,
                      pretrain={"days": 1, "epochs": 1, "batch_size": 64, "learning_rate": 1e-3})
    lines = []
    train(cfg, tmp_path, log=lines.append, evaluate=False)
    assert any("sharpened" in line for line in lines)
    warm = torch.load(tmp_path / "model_warmstart.pt", weights_only=True)["actor_state_dict"]
    first = torch.load(tmp_path / "model_0.pt", weights_only=True)["actor_state_dict"]
    outputs = {f"mlp.{_last_index(warm, 'mlp.')}",
               f"node_scorer.{_last_index(warm, 'node_scorer.')}"}
    scaled = 0
    for key, value in warm.items():
        if key.rsplit(".", 1)[0] in outputs:
            torch.testing.assert_close(first[key], value / 0.5)
            scaled += 1
        else:
            assert torch.equal(first[key], value), key
    assert scaled == 4  # two weights and two biases
    with pytest.raises(ConfigError, match="warm_start_temperature"):
        tiny_config("multi_agent", warm_start_temperature=0.0)
    # With no warm start there is nothing to sharpen: refused, not ignored.
    with pytest.raises(ConfigError, match="warm_start_temperature: sharpens the warm start"):
        tiny_config("multi_agent", warm_start_temperature=0.5)


def _last_index(state: dict, prefix: str) -> int:
    """The largest layer index under ``prefix`` in a state dict (``mlp.4.weight`` -> 4)."""
    return max(int(k[len(prefix):].split(".")[0]) for k in state if k.startswith(prefix))


def test_warmup_ppo_freezes_the_actor_for_the_first_updates(monkeypatch):
    from rsl_rl.algorithms import PPO

    from agents.training.ppo import WarmupPPO

    seen = []
    monkeypatch.setattr(PPO, "update", lambda self: seen.append(
        all(p.requires_grad for p in self.actor.parameters())) or {})
    alg = WarmupPPO.__new__(WarmupPPO)  # the update logic alone, without rsl_rl's set-up
    alg.actor = torch.nn.Linear(2, 2)
    alg.critic_warmup_updates, alg.updates_done, alg.schedule = 2, 0, "fixed"
    for _ in range(4):
        alg.update()
    assert seen == [False, False, True, True]
    assert all(p.requires_grad for p in alg.actor.parameters())
    alg.updates_done, alg.critic_warmup_updates = 5, 3  # resumed past the warm-up: untouched
    alg.update()
    assert seen[-1] is True


def test_linear_schedule_decays_the_learning_rate_to_zero_over_the_run(monkeypatch):
    from rsl_rl.algorithms import PPO

    from agents.training.ppo import WarmupPPO

    rates = []
    monkeypatch.setattr(PPO, "update", lambda self: rates.append(
        (self.learning_rate, self.optimizer.param_groups[0]["lr"])) or {})
    alg = WarmupPPO.__new__(WarmupPPO)
    alg.actor = torch.nn.Linear(2, 2)
    alg.optimizer = torch.optim.Adam(alg.actor.parameters(), lr=1e-3)
    alg.critic_warmup_updates, alg.updates_done, alg.schedule = 0, 0, "linear"
    alg.initial_learning_rate, alg.total_updates = 1e-3, 4
    for _ in range(4):
        alg.update()
    assert [r for r, _ in rates] == pytest.approx([1e-3, 7.5e-4, 5e-4, 2.5e-4])
    assert all(a == b for a, b in rates)  # the optimiser uses the rate it reports
    alg.updates_done = 2  # a resumed run picks the schedule up where it stopped
    alg.update()
    assert rates[-1][0] == pytest.approx(5e-4)


def test_a_file_carrying_code_is_refused_by_every_loader_and_never_run(tmp_path, capsys):
    """A pickle whose loading would create a file, handed to evaluation, rendering, a resumed
    run and a resumed warm start: each refuses it with a one-line error; the file never exists."""
    from agents.evaluate import main as evaluate_main
    from agents.training.cli import main as train_main
    from agents.render import main as render_main

    marker = tmp_path / "ran"
    hostile = {"actor_state_dict": {}, "critic_state_dict": {}, "optimizer_state_dict": {},
               "iter": 1, "infos": _RunsCode(str(marker))}
    evil = tmp_path / "evil.pt"
    torch.save(hostile, evil)

    assert evaluate_main(["--agents", str(evil), "--episodes", "1", "--out", str(tmp_path / "e")]) == 2
    assert "corrupt or not a torch file" in capsys.readouterr().err
    assert render_main(["--agent", str(evil), "--minutes", "2", "--out", str(tmp_path / "r.gif")]) == 2
    assert "corrupt or not a torch file" in capsys.readouterr().err

    # A real run's last checkpoint replaced by the hostile file, then resumed.
    run = tmp_path / "run"
    train(tiny_config("single_agent", iterations=1, env_config="small"), run,
          log=lambda *_: None, evaluate=False)
    (last,) = sorted(run.glob("model_*.pt"))[-1:]
    torch.save(hostile, last)
    assert train_main(["--resume", str(run), "--no-eval"]) == 2
    err = capsys.readouterr().err
    assert f"checkpoint {last} cannot be loaded into this run" in err and len(err.strip().splitlines()) == 1

    # A hostile warm-start progress file (what a run stopped during its warm start resumes from;
    # test_run_killed_during_the_warm_start_resumes_it goes through that path).
    from agents.training.imitation import load_warm_start_state

    torch.save({"next_round": 1, "data": _RunsCode(str(marker))}, run / "warmstart_state.pt")
    with pytest.raises(ValueError, match="not a readable warm-start state.*tensors and plain data only"):
        load_warm_start_state(run / "warmstart_state.pt")
    assert not marker.exists()


def test_checkpoint_with_non_finite_weights_is_refused_naming_the_weight(tmp_path):
    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    name = sorted(data["actor_state_dict"])[3]
    data["actor_state_dict"][name] = data["actor_state_dict"][name].clone().fill_(float("nan"))
    torch.save(data, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match=f"weight '{re.escape(name)}' has NaN or infinite"):
        GCNController(tmp_path / "nan.pt")
    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    data["actor_state_dict"].pop(name)
    torch.save(data, tmp_path / "short.pt")
    with pytest.raises(CheckpointError, match="do not fit the GCN actor") as exc:
        GCNController(tmp_path / "short.pt")
    assert "\n" not in str(exc.value)


def _observations(n: int = 12) -> list[dict]:
    """AEC observations with a choice (two or more legal actions) from a random day of `paper`."""
    from marl_vertiport.vertiport_v0 import raw_env

    env = raw_env(config="paper")
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    out = []
    while len(out) < n:
        obs = env.observe(env.agent_selection)
        if obs["action_mask"].sum() > 1:
            out.append(obs)
        env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    env.close()
    return out


def test_an_ensemble_takes_the_legal_action_of_largest_mean_log_probability(tmp_path):
    """`a.pt+b.pt` is the ensemble of both checkpoints: with itself a checkpoint plays as
    alone; with another, the action is the argmax of the members' mean log-probabilities."""
    from agents.controllers.registry import AgentSpecError, make_controller
    from agents.gcn.distribution import masked_logits
    from agents.controllers.gcn import GCNController, GCNEnsemble

    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    gen = torch.Generator().manual_seed(0)
    data["actor_state_dict"] = {k: v + 0.3 * torch.randn(v.shape, generator=gen)
                                for k, v in data["actor_state_dict"].items()}
    other = tmp_path / "other.pt"
    torch.save(data, other)
    alone, second = GCNController(SHIPPED_CHECKPOINT), GCNController(other)
    twice = make_controller(f"{SHIPPED_CHECKPOINT}+{SHIPPED_CHECKPOINT}")
    pair = make_controller(f"gcn+{other}")
    assert isinstance(pair, GCNEnsemble) and pair.name.startswith("gcn-ensemble:")
    disagree = 0
    for obs in _observations():
        assert twice.act(obs) == alone.act(obs)
        logps = []
        for member in (alone, second):
            t = member.checked_tensors(obs)
            logps.append(torch.log_softmax(masked_logits(member.actor.logits(t),
                                                         t["action_mask"]), -1)[0])
        expected = int(torch.where(torch.as_tensor(obs["action_mask"], dtype=torch.bool),
                                   (logps[0] + logps[1]) / 2, -torch.inf).argmax())
        assert pair.act(obs) == expected and obs["action_mask"][expected] == 1
        disagree += alone.act(obs) != second.act(obs)
    assert disagree > 0  # the members differ, so the check above compares something
    with pytest.raises(AgentSpecError, match="missing.pt"):
        make_controller(f"gcn+{tmp_path / 'missing.pt'}")
    with pytest.raises(Exception, match="two or more"):
        GCNEnsemble([SHIPPED_CHECKPOINT])
