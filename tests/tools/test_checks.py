"""``marl-vertiport check-train``: a training run paired with the shipped checkpoint, M, the
verdict (agents/checks/train.py)."""

from __future__ import annotations

import json

import pytest

from agents.checks import train as check
from agents.controllers.registry import SHIPPED_CHECKPOINT

QUICK = ["--episodes", "1", "--set", "schedule.episode_steps=30", "--workers", "1",
         "--no-progress"]


def stats(low: float, high: float, lost: float) -> dict:
    reward = {"base": 1000.0, "candidate": 1000.0 + (low + high) / 2, "difference": (low + high) / 2,
              "ci_low": low, "ci_high": high, "days": 200}
    return {"total_reward": reward, "stranded": {"base": 1.0, "candidate": 1.0 + lost,
                                                 "difference": lost, "ci_low": lost,
                                                 "ci_high": lost, "days": 200}}


@pytest.mark.parametrize("low, high, lost, equivalent", [
    (-40, 35, 0.05, True),
    (-40, 35, -0.10, True),      # the bound itself counts as within
    (-40, 35, 0.15, False),      # more vehicles lost
    (-90, 10, 0.0, False),       # the interval reaches past -M
    (20, 85, 0.0, False),        # or past +M
])
def test_the_verdict_needs_the_interval_within_m_and_the_losses_within_their_bound(
        low, high, lost, equivalent):
    same, reasons = check.verdict(stats(low, high, lost), 80.0, 0.1)
    assert same is equivalent
    assert len(reasons) == 2 and "±80" in reasons[0] and "±0.10" in reasons[1]


def test_the_shipped_checkpoint_is_equivalent_to_itself(tmp_path, capsys):
    cfg = tmp_path / "check.yaml"
    cfg.write_text("configs: [paper, small]\nseeds: '800200:800202'\nreward_margin: 50\n"
                   "margin_note: a test\n")
    out = tmp_path / "out"
    assert check.main(["--checkpoint", str(SHIPPED_CHECKPOINT), "--config", str(cfg),
                       "--out", str(out), *QUICK]) == 0
    printed = capsys.readouterr().out
    assert "bit-identical to the shipped checkpoint's" in printed
    assert "M = 50: a test" in printed and "verdict: EQUIVALENT (a quick look" in printed
    report = json.loads((out / "check.json").read_text())
    assert report["equivalent"] and report["stats"]["total_reward"]["difference"] == 0.0
    assert report["days"].startswith("2 validation days: paper, small x seeds 800200-800200")
    assert (out / "eval" / "episodes.csv").exists()


def test_margin_is_the_spread_of_the_seeds_mean_rewards(tmp_path, capsys):
    cfg = tmp_path / "check.yaml"
    cfg.write_text("configs: [paper]\nseeds: '800200:800202'\n")
    assert check.main(["--margin", str(SHIPPED_CHECKPOINT), "gcn_copy.pt", "--config", str(cfg),
                       "--out", str(tmp_path / "m"), *QUICK]) == 2  # a missing file: refused
    assert "gcn_copy.pt: no such file" in capsys.readouterr().err
    copy = tmp_path / "gcn_copy.pt"
    copy.write_bytes(SHIPPED_CHECKPOINT.read_bytes())
    assert check.main(["--margin", str(SHIPPED_CHECKPOINT), str(copy), "--config", str(cfg),
                       "--out", str(tmp_path / "m"), *QUICK]) == 0
    assert "M = 0.0" in capsys.readouterr().out
    report = json.loads((tmp_path / "m" / "check.json").read_text())
    assert report["margin"] == 0.0 and report["lost_margin"] == 0.0 and len(report["runs"]) == 2


def test_the_margins_are_the_largest_differences_of_the_seeds_means(monkeypatch):
    days = {"a": [(10.0, 0.5), (14.0, 0.5)], "b": [(4.0, 1.0), (6.0, 0.5)], "c": [(8.0, 0.0)] * 2}
    monkeypatch.setattr(check, "_by_day", lambda _evaluation, agent: {
        k: {"total_reward": r, "stranded": lost} for k, (r, lost) in enumerate(days[agent])})
    measured = check.spread(None, ["a", "b", "c"])
    assert measured["margin"] == 12.0 - 5.0 and measured["lost_margin"] == 0.75
    assert measured["runs"]["b"] == {"reward": 5.0, "lost": 0.75, "days": 2}


@pytest.mark.parametrize("text, message", [
    ("seeds: '1:5'\n", "seeds: seed range '1:5' reaches into the training seeds"),
    ("reward_margin: -3\n", "reward_margin: must be a finite number >= 0"),
    ("reward_margn: 3\n", "reward_margn: unknown key"),
])
def test_a_broken_check_config_is_refused_naming_the_key(tmp_path, capsys, text, message):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    assert check.main(["--checkpoint", str(SHIPPED_CHECKPOINT), "--config", str(cfg)]) == 2
    assert message in capsys.readouterr().err


def test_the_shipped_check_config_names_real_configs_and_validation_days():
    from agents.common.seeds import EVAL_SEED_BASE, VALIDATION_SEED_BASE
    from agents.training.config import load_train_config
    from marl_vertiport import load_config

    cfg = check.load_check_config()
    days = check.parse_seed_range(cfg.seeds)
    assert VALIDATION_SEED_BASE <= days.start and days.stop <= EVAL_SEED_BASE
    assert len(cfg.configs) * len(days) >= 200
    assert set(cfg.configs) == set(load_train_config(cfg.train_config).scenarios)
    for name in cfg.configs:
        load_config(name)
    assert cfg.reward_margin > 0 and 0 < cfg.lost_margin <= 0.5
