"""Training runs: save, reload and resume, a divergence stop, a run killed in PPO or in the warm
start, the log writer's callback, the sharpened warm start and the PPO schedule."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from agents.controllers.gcn import GCNController
from agents.training.callbacks import TrainingDiverged
from agents.training.checkpoints import latest_checkpoint
from agents.training.config import TrainConfig
from agents.training.curves import read_curves
from agents.training.pipeline import train
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution
from helpers import tiny_config


@pytest.mark.parametrize("mode", ["multi_agent", "single_agent"])
def test_two_iteration_training_save_reload_and_resume(tmp_path, mode):
    teacher = "planner" if mode == "multi_agent" else "dispatcher"
    cfg = tiny_config(mode, pretrain={"days": 2, "day_steps": 24, "teacher": teacher,
                                      "planner_horizon": 4, "workers": 1, "epochs": 1,
                                      "batch_size": 64, "learning_rate": 1e-3, "dagger_rounds": 1,
                                      "dagger_epochs": 2},
                      critic_warmup_iterations=1)
    lines: list[str] = []
    final = train(cfg, tmp_path, log=lambda line, *_: lines.append(str(line)), evaluate=False)
    # Behaviour cloning fits `epochs` passes, the DAgger round `dagger_epochs`; each round is timed.
    assert any("demonstrations epoch 1/1" in line for line in lines)
    assert any("DAgger round 1 epoch 2/2" in line for line in lines)
    assert any(line.strip().startswith("DAgger round 1: days") for line in lines)
    assert final.name == "model_1.pt" and (tmp_path / "model_0.pt").exists()
    warm = torch.load(tmp_path / "model_warmstart.pt", weights_only=True)["infos"]["warm_start"]
    # Two fits (behaviour cloning, one DAgger round), each scored; the best one is kept.
    assert {"fit_0_score", "fit_1_score"} <= set(warm) and "fit_2_score" not in warm
    assert warm["chosen_fit"] == max((0, 1), key=lambda k: warm[f"fit_{k}_score"])
    kept = GCNController(tmp_path / f"model_fit{int(warm['chosen_fit'])}.pt").actor.state_dict()
    for key, value in GCNController(tmp_path / "model_warmstart.pt").actor.state_dict().items():
        torch.testing.assert_close(kept[key], value)  # every fit is written; the kept one warm-starts
    assert not (tmp_path / "model_fit2.pt").exists()
    assert (tmp_path / "curves.csv").exists() and (tmp_path / "learning_curves.png").exists()
    assert not list(tmp_path.glob("*.tmp"))
    ctl = GCNController(final)
    from agents.controllers.episode import run_aec_episode
    from marl_vertiport import vertiport_v1

    metrics = run_aec_episode(vertiport_v1.env(**{"schedule.episode_steps": 20}), ctl, 1)
    assert metrics["steps"] == 20
    # Resume to 3 iterations: continues from model_1 and writes model_2.
    cfg3 = build_dataclass(TrainConfig, {**to_dict(cfg), "iterations": 3})
    final3 = train(cfg3, tmp_path, resume=True, log=lambda *_: None, evaluate=False)
    assert final3.name == "model_2.pt"
    rows = read_curves(tmp_path / "curves.csv")
    assert [int(r["iteration"]) for r in rows] == [0, 1, 2]
    # The actor is frozen in iteration 0 (the warm start's fits leave no gradient to count)
    # and takes a gradient in the others.
    assert rows[0]["actor_grad_norm"] == 0 and rows[0]["actor_clip_fraction"] == 0
    assert all(r["actor_grad_norm"] > 0 and 0 <= r["actor_clip_fraction"] <= 1 for r in rows[1:])

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
                                "low_battery_starts": 1, "noise": 0.2, "teacher": "dispatcher",
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

def test_grad_norm_probe_reads_the_actors_gradient_before_the_clip():
    """The probe's norm is the actor's gradient norm as the backward pass leaves it, not as
    the clip leaves it; a step in which the actor is frozen is not counted, and WarmupPPO
    reports the mean norm and the share of steps above ``max_grad_norm``."""
    from agents.training.ppo import GradNormProbe

    torch.manual_seed(0)
    actor, critic = torch.nn.Linear(3, 2), torch.nn.Linear(3, 1)
    optimizer = torch.optim.SGD(list(actor.parameters()) + list(critic.parameters()), lr=0.1)
    probe = GradNormProbe(actor, optimizer)
    x = torch.randn(16, 3)
    actor(x).sum().backward()  # a gradient outside the optimiser's steps (an imitation fit)
    probe.reset()
    expected = []
    for scale in (1.0, 100.0):
        optimizer.zero_grad()
        (scale * actor(x).pow(2).mean() + critic(x).mean()).backward()
        expected.append(float(torch.linalg.vector_norm(
            torch.cat([p.grad.flatten() for p in actor.parameters()]))))
        torch.nn.utils.clip_grad_norm_(actor.parameters(), 0.5)
        optimizer.step()
    actor.requires_grad_(False)  # frozen: only the critic steps
    optimizer.zero_grad()
    critic(x).mean().backward()
    optimizer.step()
    norms = probe.pop()
    assert norms == pytest.approx(expected, rel=1e-6) and expected[1] > 0.5
    assert probe.pop() == []


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


def test_ppo_can_start_from_a_checkpoint_in_place_of_the_warm_start(tmp_path):
    """``init_checkpoint``: the run reads the checkpoint's actor and critic (weights only, not
    its iteration), keeps them as model_warmstart.pt, and PPO's first iteration (actor frozen)
    holds that actor; a missing file, a model of another shape and a warm start beside it are
    refused with the key named."""
    source = tmp_path / "source"
    train(tiny_config("multi_agent", iterations=2), source, log=lambda *_: None, evaluate=False)
    start = torch.load(source / "model_1.pt", weights_only=True)
    run = tmp_path / "run"
    cfg = tiny_config("multi_agent", iterations=1, critic_warmup_iterations=1,
                      init_checkpoint=str(source / "model_1.pt"))
    lines: list[str] = []
    final = train(cfg, run, log=lines.append, evaluate=False)
    assert final.name == "model_0.pt"  # iteration 0 of this run, not the source's 2
    assert any("PPO starts from" in line for line in lines)
    warm = torch.load(run / "model_warmstart.pt", weights_only=True)
    first = torch.load(final, weights_only=True)
    for part in ("actor_state_dict", "critic_state_dict"):
        for key, value in start[part].items():
            assert torch.equal(warm[part][key], value), (part, key)
    for key, value in start["actor_state_dict"].items():
        assert torch.equal(first["actor_state_dict"][key], value), key  # frozen: unchanged
    (row,) = read_curves(run / "curves.csv")
    assert row["actor_grad_norm"] == 0 and row["actor_clip_fraction"] == 0  # and no gradient
    missing = build_dataclass(TrainConfig, {**to_dict(cfg), "init_checkpoint": str(tmp_path / "no.pt")})
    with pytest.raises(ConfigError, match="init_checkpoint: .*no such file"):
        train(missing, tmp_path / "missing", log=lambda *_: None, evaluate=False)
    other = build_dataclass(TrainConfig, {**to_dict(cfg),
                                          "model": {"hidden": 8, "hidden_dims": [8]}})
    with pytest.raises(ValueError, match="cannot be loaded into this run"):
        train(other, tmp_path / "other", log=lambda *_: None, evaluate=False)
    with pytest.raises(ConfigError, match="init_checkpoint: cannot start an ensemble"):
        tiny_config("multi_agent", init_checkpoint="x.pt",
                    pretrain={"days": 1, "epochs": 1, "batch_size": 64, "learning_rate": 1e-3},
                    ensemble={"fits": 2})
    tiny_config("multi_agent", init_checkpoint="x.pt", warm_start_temperature=0.5)  # accepted


def test_a_warm_start_goes_on_from_the_init_checkpoint(tmp_path):
    """``init_checkpoint`` with a warm start: the checkpoint's actor drives the first round (the
    teacher labels the states it visits) and is scored there; the fit starts from its weights."""
    source = tmp_path / "source"
    train(tiny_config("multi_agent", iterations=1), source, log=lambda *_: None, evaluate=False)
    pretrain = {"days": 1, "day_steps": 40, "starts": 0, "epochs": 1, "batch_size": 64,
                "learning_rate": 1e-9, "teacher": "dispatcher", "workers": 1}
    cfg = tiny_config("multi_agent", iterations=1, critic_warmup_iterations=1,
                      init_checkpoint=str(source / "model_0.pt"), pretrain=pretrain)
    lines: list[str] = []
    train(cfg, tmp_path / "run", log=lines.append, evaluate=False)
    text = "\n".join(lines)
    assert "the warm start goes on from" in text and "the starting policy scores" in text
    assert "demonstrations: 1 days and 0 day starts of 120 steps (0 with low batteries), the actor drives" in text
    start = torch.load(source / "model_0.pt", weights_only=True)["actor_state_dict"]
    warm = torch.load(tmp_path / "run" / "model_warmstart.pt", weights_only=True)["actor_state_dict"]
    # A learning rate of 1e-9: one pass leaves the fit where the checkpoint put it.
    assert all(torch.allclose(warm[k], v, atol=1e-6) for k, v in start.items())
    cold = tiny_config("multi_agent", iterations=1, critic_warmup_iterations=1, pretrain=pretrain)
    lines.clear()
    train(cold, tmp_path / "cold", log=lines.append, evaluate=False)
    assert "the dispatcher drives" in "\n".join(lines)


def test_resume_with_more_rounds_goes_on_from_the_saved_warm_start(tmp_path, capsys):
    """``train --resume RUN --rounds N``: a finished run's warm start goes on to N DAgger rounds
    and ends as a run made with N; PPO's old outputs are moved aside, not lost."""
    import yaml

    from agents.training.cli import main
    from agents.training.config import load_train_config

    cfg = tiny_config("single_agent", iterations=1,
                      pretrain={"days": 1, "day_steps": 24, "teacher": "dispatcher",
                                "workers": 1, "epochs": 1, "batch_size": 64,
                                "learning_rate": 1e-3, "dagger_rounds": 0})
    path = tmp_path / "zero.yaml"
    path.write_text(yaml.safe_dump(to_dict(cfg)))
    run = tmp_path / "run"
    assert main(["--config", str(path), "--run-dir", str(run), "--no-eval"]) == 0
    old_ppo = (run / "model_0.pt").read_bytes()
    assert main(["--resume", str(run), "--rounds", "1", "--no-eval"]) == 0
    assert (run / "after_0_rounds" / "model_0.pt").read_bytes() == old_ppo
    assert (run / "after_0_rounds" / "curves.csv").exists() and (run / "model_fit1.pt").exists()
    assert load_train_config(run / "train_config.yaml").pretrain.dagger_rounds == 1
    assert [r["round"] for r in read_curves(run / "warmstart.csv")] == [0.0, 1.0, 2.0]
    straight = build_dataclass(TrainConfig, {**to_dict(cfg), "pretrain": {
        **to_dict(cfg.pretrain), "dagger_rounds": 1}})
    train(straight, tmp_path / "straight", log=lambda *_: None, evaluate=False)
    for name in ("model_warmstart.pt", "model_0.pt"):
        made = torch.load(run / name, weights_only=True)["actor_state_dict"]
        for key, value in torch.load(tmp_path / "straight" / name,
                                     weights_only=True)["actor_state_dict"].items():
            assert torch.equal(value, made[key]), (name, key)
    capsys.readouterr()
    # Not more rounds than it has, or not with a new run: refused before anything is touched.
    assert main(["--resume", str(run), "--rounds", "1", "--no-eval"]) == 2
    assert main(["--config", str(path), "--rounds", "2", "--no-eval"]) == 2
    err = capsys.readouterr().err
    assert "it can only go on to more" in err and "only with --resume" in err
    assert load_train_config(run / "train_config.yaml").pretrain.dagger_rounds == 1
