"""Which warm-start fit goes on to PPO (agents/training/fit_selection.py, ``pretrain.keep``):
each rule's choice, and the paired rule's scores are every fit's own days, the same for all."""

import numpy as np
import pytest
import torch

from agents.training.config import TrainConfig
from agents.training.fit_selection import day_score, kept_fit
from agents.training.demonstrations import label_day, round_tasks
from agents.training.imitation import load_warm_start_state, warm_start
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict

from helpers import small_actor


def _config(**pretrain) -> TrainConfig:
    """A small model and a warm start of heuristic-driven days with no day starts."""
    return build_dataclass(TrainConfig, {**to_dict(TrainConfig()),
                                         "model": {"hidden": 16, "hidden_dims": [32]},
                                         "pretrain": {"starts": 0, "low_battery_starts": 0,
                                                      "epochs": 1, "teacher": "dispatcher",
                                                      "workers": 1, "batch_size": 64,
                                                      "keep": "paired", **pretrain}})


def test_each_rule_keeps_its_fit():
    scores, paired = [10.0, 30.0, 20.0], [25.0, 5.0, 15.0]
    assert kept_fit("round", scores, paired) == 1
    assert kept_fit("paired", scores, paired) == 0
    assert kept_fit("last", scores, paired) == 2
    assert kept_fit("round", [float("nan"), 1.0]) == 1  # a fit with no full day is never kept
    assert kept_fit("paired", [7.0], [7.0]) == 0  # behaviour cloning alone: its one fit
    with pytest.raises(ValueError, match="same days"):
        kept_fit("paired", scores, paired[:2])
    with pytest.raises(ConfigError, match="pretrain.keep"):
        build_dataclass(TrainConfig, {**to_dict(TrainConfig()), "pretrain": {"keep": "best"}})


def test_paired_scores_are_every_fit_on_the_last_rounds_days(tmp_path):
    torch.manual_seed(0)
    env_cfg = to_dict(load_config("paper"))
    cfg = _config(days=2, day_steps=40, dagger_rounds=1)
    actor = small_actor()
    lines: list[str] = []
    events: list[str] = []
    made: dict[int, dict] = {}

    def on_fit(k, content):
        events.append(f"fit {k}")
        made[k] = content

    stats = warm_start(actor, cfg, env_cfg, log=lines.append, state_path=tmp_path / "state.pt",
                       on_round=lambda record: events.append("round"), on_fit=on_fit)
    assert any(line.startswith("scoring the 2 fits on the same days") for line in lines)
    fits = load_warm_start_state(tmp_path / "state.pt")["fits"]
    # Each fit is handed over as soon as its round ends, before the next round's days.
    assert events == ["round", "fit 0", "round", "fit 1", "round"]
    for k, fit in enumerate(fits):
        torch.testing.assert_close(made[k]["actor_state_dict"], fit["actor_state_dict"])
    events.clear()  # a resumed (here finished) warm start hands over the fits made before
    warm_start(small_actor(), cfg, env_cfg, log=lambda *_: None, state_path=tmp_path / "state.pt",
               on_round=lambda record: events.append("round"), on_fit=on_fit)
    assert events == ["round"] * 3 + ["fit 0", "fit 1"]
    # Each fit drives the last round's days by itself: its paired score is their mean score.
    for k, fit in enumerate(fits):
        days = [label_day(t)[1] for t in round_tasks(cfg, env_cfg, 2, fit, last=True)]
        assert stats[f"fit_{k}_paired_score"] == pytest.approx(
            np.mean([day_score(m, cfg.lost_vehicle_penalty) for m in days]))
    assert stats["fit_1_paired_score"] == pytest.approx(stats["fit_1_score"])  # the last fit's days
    scores = [stats[f"fit_{k}_score"] for k in (0, 1)]
    paired = [stats[f"fit_{k}_paired_score"] for k in (0, 1)]
    assert stats["chosen_fit"] == kept_fit("paired", scores, paired)
    for key, value in actor.state_dict().items():  # the actor holds the kept fit
        torch.testing.assert_close(value, fits[int(stats["chosen_fit"])]["actor_state_dict"][key])


def test_paired_keep_without_dagger_keeps_behaviour_cloning():
    cfg = _config(days=1, day_steps=30)
    stats = warm_start(small_actor(), cfg, to_dict(load_config("paper")), log=lambda *_: None)
    assert stats["chosen_fit"] == 0
    assert stats["fit_0_paired_score"] == pytest.approx(stats["fit_0_score"])


def test_a_finished_warm_start_goes_on_to_more_rounds_as_if_made_so(tmp_path):
    """Progress saved with one DAgger round, resumed with two: the scoring round is replaced by
    the second DAgger round, and fits, scores, records and the kept fit are a two-round run's."""
    env_cfg = to_dict(load_config("paper"))
    one, two = _config(days=1, day_steps=30, dagger_rounds=1), _config(days=1, day_steps=30,
                                                                       dagger_rounds=2)
    results = {}
    for name, steps in (("straight", [two]), ("extended", [one, two])):
        records = []
        for cfg in steps:
            torch.manual_seed(0)
            records.clear()
            lines: list[str] = []
            stats = warm_start(small_actor(), cfg, env_cfg, log=lines.append,
                               state_path=tmp_path / f"{name}.pt", on_round=records.append)
        results[name] = stats, list(records), load_warm_start_state(tmp_path / f"{name}.pt"), lines
    (stats, records, state, _), (ext_stats, ext_records, ext_state, lines) = results.values()
    assert "warm start: going on from 1 to 2 DAgger rounds" in lines
    assert stats == ext_stats and records == ext_records and len(ext_state["fits"]) == 3
    assert state["env_steps"] == ext_state["env_steps"] and state["scores"] == ext_state["scores"]
    for fit, ext_fit in zip(state["fits"], ext_state["fits"]):
        for key, value in fit["actor_state_dict"].items():
            assert torch.equal(value, ext_fit["actor_state_dict"][key]), key
    # Fewer rounds than saved, or any other change, is refused.
    with pytest.raises(ValueError, match="not fewer"):
        warm_start(small_actor(), one, env_cfg, log=lambda *_: None,
                   state_path=tmp_path / "straight.pt")
    with pytest.raises(ValueError, match="another configuration"):
        warm_start(small_actor(), _config(days=2, day_steps=30, dagger_rounds=3), env_cfg,
                   log=lambda *_: None, state_path=tmp_path / "straight.pt")
