"""The refit study (agents/studies/refit.py): a run's warm-start data fit again from fresh
weights, one checkpoint per seed, reproducible, loadable like the run's own."""

import pytest
import torch

from agents.controllers.gcn import GCNController
from agents.training.config import TrainConfig
from agents.training.pipeline import train
from agents.studies.refit import main, refit
from marl_vertiport.config import build_dataclass, to_dict


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    base = to_dict(TrainConfig())
    base.update(mode="multi_agent", num_envs=2, num_steps_per_env=8, iterations=1,
                save_interval=1, critic_warmup_iterations=0,
                pretrain={"days": 1, "day_steps": 40, "starts": 1, "start_steps": 12,
                          "low_battery_starts": 0, "teacher": "dispatcher", "workers": 1,
                          "epochs": 2, "batch_size": 32, "learning_rate": 1e-3},
                evaluation={"episodes": 0, "agents": []})
    train(build_dataclass(TrainConfig, base), folder, log=lambda *_: None, evaluate=False)
    return folder


def test_refits_differ_by_seed_reproduce_per_seed_and_load(run, tmp_path):
    first = refit(run, [1, 2], tmp_path / "a", log=lambda *_: None)
    again, = refit(run, [1], tmp_path / "b", log=lambda *_: None)
    weights = [torch.load(p, weights_only=True)["actor_state_dict"] for p in first]
    warm = torch.load(run / "model_warmstart.pt", weights_only=True)["actor_state_dict"]
    repeat = torch.load(again, weights_only=True)["actor_state_dict"]
    assert [p.name for p in first] == ["model_refit1.pt", "model_refit2.pt"]
    assert all(torch.equal(weights[0][k], repeat[k]) for k in warm)
    assert not all(torch.equal(weights[0][k], weights[1][k]) for k in warm)
    assert not all(torch.equal(weights[0][k], warm[k]) for k in warm)
    info = torch.load(first[0], weights_only=True)["infos"]["refit"]
    assert info["seed"] == 1 and info["samples"] > 0
    from marl_vertiport.vertiport_v1 import raw_env

    controller = GCNController(first[1])
    env = raw_env(config=controller.train_info["env_config"])
    env.reset(seed=3)
    obs = env.observe(env.agent_selection)
    assert obs["action_mask"][controller.act(obs)] == 1
    env.close()


def test_a_folder_without_a_warm_start_is_named(tmp_path, capsys):
    assert main([str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "no train_config.yaml" in capsys.readouterr().err
    assert main([str(tmp_path), "--seeds", "1", "1", "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()
