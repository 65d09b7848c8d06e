"""Imitation warm start: demonstration days keep only steps with a choice, with legal labels,
and DAgger days are driven by the learner."""

import numpy as np
import pytest
import torch

from agents.training.demonstrations import (
    DayTask, _with_battery, collect, label_day, make_teacher, round_tasks,
)
from agents.training.imitation import _learner, fit_actor, label_weights
from agents.training.config import TrainConfig
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict
from marl_vertiport.vertiport_v1 import raw_env

from helpers import small_actor


def test_demonstration_day_keeps_choices_with_legal_labels():
    env_cfg = to_dict(load_config("paper"))
    data, metrics = label_day(DayTask(env_cfg, seed=7, steps=60, teacher="planner", planner_horizon=4))
    n = len(data["label"])
    assert 0 < n < 60 and metrics["steps"] == 60
    assert data["evtol_nodes"].shape == (n, 4, 13) and data["port_nodes"].shape == (n, 10, 4)
    assert (data["action_mask"].sum(axis=1) > 1).all()  # only steps with a choice
    assert data["action_mask"][np.arange(n), data["label"]].all()  # every label legal
    assert data["regret"].shape == (n,) and (data["regret"] >= 0).all()
    assert (data["regret"] > 0).any()  # the planner simulated some decisions
    np.testing.assert_allclose(label_weights(np.array([0.0, 3.0, 500.0, np.inf]), 50.0), [1.0, 4.0, 51.0, 51.0])
    np.testing.assert_allclose(label_weights(np.array([0.0, 3.0]), 0.0), [1.0, 1.0])


def test_fit_then_learner_drives_a_dagger_day():
    torch.manual_seed(0)
    env_cfg = to_dict(load_config("paper"))
    data, _ = collect([DayTask(env_cfg, s, 80, "dispatcher", 4) for s in (1, 2)], 1,
                      lambda *_: None, "demo")
    actor = small_actor()
    first = fit_actor(actor, data, 1, 64, 1e-3, 0, lambda *_: None, "bc", regret_cap=50.0)
    last = fit_actor(actor, data, 80, 64, 1e-3, 0, lambda *_: None, "bc")
    assert last["cross_entropy"] < first["cross_entropy"] and last["accuracy"] > 0.8
    cfg = build_dataclass(TrainConfig, {**to_dict(TrainConfig()),
                                        "model": {"hidden": 16, "hidden_dims": [32]}})
    learner = _learner(actor, env_cfg, cfg)
    dagger, metrics = label_day(DayTask(env_cfg, 3, 40, "dispatcher", 4, learner=learner))
    assert metrics["steps"] == 40 and len(dagger["label"]) > 0
    # A scoring day: the same learner drives the same day, no teacher runs, nothing is returned.
    scored, same = label_day(DayTask(env_cfg, 3, 40, "planner", 4, learner=learner, labelled=False))
    assert same == metrics and all(len(v) == 0 for v in scored.values())
    assert scored["evtol_nodes"].shape == (0, 4, 13) and scored["action_mask"].dtype == np.int8
    with pytest.raises(ValueError, match="learner"):
        label_day(DayTask(env_cfg, 3, 40, "dispatcher", 4, labelled=False))
    with pytest.raises(ValueError, match="teacher"):
        make_teacher("oracle", 4, 0.0, 0)
    # The guarded planner: the planner decides, the dispatcher flies the guard's rollouts.
    from agents.controllers.dispatcher import DispatcherController
    from agents.controllers.guard import GuardController
    from agents.controllers.planner import PlannerController

    guarded = make_teacher("guarded_planner", 4, 3.0, 7)
    assert isinstance(guarded, GuardController) and isinstance(guarded.proposer, PlannerController)
    assert isinstance(guarded.own_rollout_policy, DispatcherController)
    assert (guarded.proposer.horizon, guarded.proposer.margin, guarded.settings.seed) == (4, 3.0, 7)
    day, _ = label_day(DayTask(env_cfg, 3, 40, "guarded_planner", 4))
    planned, _ = label_day(DayTask(env_cfg, 3, 40, "planner", 4))
    # Within 40 steps of a full fleet no choice loses a vehicle: the planner's labels stand.
    np.testing.assert_array_equal(day["label"], planned["label"])
    # The planner's options reach the planner, behind the guard too; others are refused.
    robust = make_teacher("guarded_planner", 4, 3.0, 7, expect_failures=True, rescue=True)
    assert robust.proposer.expect_failures and robust.proposer.rescue
    plain = make_teacher("planner", 4, 3.0, 7)
    assert not plain.expect_failures and not plain.rescue
    with pytest.raises(ValueError, match="planner options"):
        make_teacher("planner", 4, 3.0, 7, nominal=False)


def test_noise_changes_the_path_not_the_labels_and_low_battery_starts(monkeypatch):
    import agents.training.demonstrations as demonstrations

    env_cfg = to_dict(load_config("paper"))
    clean, _ = label_day(DayTask(env_cfg, 5, 60, "dispatcher", 4))
    chosen: list[int] = []
    original = demonstrations.make_teacher

    def recording_teacher(*args, **kwargs):
        teacher = original(*args, **kwargs)
        act = teacher.act
        teacher.act = lambda obs: chosen.append(int(act(obs))) or chosen[-1]
        return teacher

    monkeypatch.setattr(demonstrations, "make_teacher", recording_teacher)
    noisy, _ = label_day(DayTask(env_cfg, 5, 60, "dispatcher", 4, noise=0.5))
    monkeypatch.setattr(demonstrations, "make_teacher", original)
    again, _ = label_day(DayTask(env_cfg, 5, 60, "dispatcher", 4, noise=0.5))
    # Random actions take the day elsewhere; the same seed draws the same ones.
    assert not np.array_equal(clean["evtol_nodes"][:20], noisy["evtol_nodes"][:20])
    np.testing.assert_array_equal(noisy["label"], again["label"])
    # Every label is the teacher's own choice in that state, whatever was then executed.
    assert noisy["label"].tolist() == chosen
    low = _with_battery(env_cfg, 45.0)
    assert env_cfg["battery"]["initial_pct"] == 100.0 and low["battery"]["initial_pct"] == 45.0
    env = raw_env(config=load_config(low))
    env.reset(seed=0)
    assert (env.unwrapped.sim.battery == 45.0).all()
    env.close()
    base = to_dict(TrainConfig())
    for key, value in (("noise", 1.0), ("low_battery_pct", []), ("low_battery_starts", 101)):
        bad = {**base, "pretrain": {**base["pretrain"], key: value}}
        with pytest.raises(ConfigError, match="pretrain"):
            build_dataclass(TrainConfig, bad)


def test_collect_gives_the_same_data_on_one_or_two_workers():
    env_cfg = to_dict(load_config("paper"))
    tasks = [DayTask(env_cfg, s, steps, "dispatcher", 4, noise=0.2)
             for s, steps in ((11, 90), (12, 20), (13, 50))]
    one, m1 = collect(tasks, 1, lambda *_: None, "one")
    two, m2 = collect(tasks, 2, lambda *_: None, "two")
    assert [m["steps"] for m in m2] == [90, 20, 50] and m1 == m2
    for key in one:
        np.testing.assert_array_equal(one[key], two[key])


def test_round_tasks_mix_seeds_noise_and_low_batteries():
    from agents.training.demonstrations import round_tasks

    cfg = TrainConfig(pretrain=build_dataclass(type(TrainConfig().pretrain), {
        "days": 2, "starts": 3, "low_battery_starts": 5, "low_battery_pct": [10, 30],
        "noise": 0.1, "day_steps": 1440, "start_steps": 120}))
    env_cfg = to_dict(load_config("paper"))
    first = round_tasks(cfg, env_cfg, 0, None, last=False)
    assert [t.steps for t in first] == [1440] * 2 + [120] * 8
    assert all(t.planner_options == {} for t in first)
    robust = TrainConfig(pretrain=build_dataclass(type(TrainConfig().pretrain), {
        "days": 1, "planner_expect_failures": True, "planner_rescue": True}))
    assert {frozenset(t.planner_options) for t in round_tasks(robust, env_cfg, 0, None, False)} == {
        frozenset({"expect_failures", "rescue"})}
    assert [t.noise for t in first] == [0.0] * 2 + [0.1] * 8  # full days score the fits: no noise
    assert [t.env_config["battery"]["initial_pct"] for t in first] == [100.0] * 5 + [10, 30, 10, 30, 10]
    scoring = round_tasks(cfg, env_cfg, 3, {"weights": 1}, last=True)
    assert [t.steps for t in scoring] == [1440] * 2 and all(t.learner for t in scoring)
    assert not any(t.labelled for t in scoring) and all(t.labelled for t in first)
    seeds = [t.seed for r in range(4) for t in round_tasks(cfg, env_cfg, r, None, last=False)]
    assert len(set(seeds)) == len(seeds) and max(seeds) < 1_000_000  # new per round, not eval seeds


def test_days_of_different_vertiports_are_padded_to_one_size():
    """A round across scenarios: the 3-eVTOL paper ports (10 nodes) and the 6-eVTOL twin
    layout (13 nodes) padded to 13 nodes and 6 eVTOLs; labels stay legal, padded node actions
    and rows are marked."""
    configs = [to_dict(load_config("paper", fleet_size=3)), to_dict(load_config("twin"))]
    cfg = build_dataclass(TrainConfig, {**to_dict(TrainConfig()), "pretrain": {
        "days": 2, "day_steps": 30, "starts": 0, "low_battery_starts": 0, "teacher": "dispatcher"}})
    tasks = round_tasks(cfg, configs, 0, None, last=False)
    assert [t.env_config["fleet_size"] for t in tasks] == [3, 6]
    data, _ = collect(tasks, 1, lambda *_: None, "demo", sizes=(13, 6))
    n = len(data["label"])
    assert data["port_nodes"].shape == (n, 13, 4) and data["evtol_nodes"].shape == (n, 6, 13)
    assert data["action_mask"].shape == (n, 17)
    assert data["action_mask"][np.arange(n), data["label"]].all()
    small = ~data["port_valid"][:, 10]  # rows of the 10-node vertiport
    assert small.any() and (~small).any()
    assert not data["action_mask"][small][:, 12:15].any()  # its padded node actions
    assert (data["evtol_valid"][small].sum(axis=1) == 3).all()
    assert (data["port_nodes"][small][:, 10:] == 0).all()
