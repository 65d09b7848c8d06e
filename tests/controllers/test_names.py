"""One name per controller, and the names before 0.2.0 still working, with a one-line note,
everywhere a name is read: specs (nested ones too), classes, arguments, train configs, suites,
sweeps, ``paired`` on older files, and the shipped result sets."""

import csv
import warnings

import pytest

from agents.common.names import RENAMED_AGENTS, RenamedWarning, canonical_spec
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.guard import GuardController, GuardedController
from agents.controllers.lookahead import HandbackController, LookaheadController
from agents.controllers.planner import PlannerController, RolloutPlanner
from agents.controllers.registry import BUILTIN, make_controller
from agents.evaluate import paired
from agents.evaluate.settings import EvalSettings, load_suite
from agents.sweep.spec import parse_sweep
from agents.training.config import load_train_config
from marl_vertiport.config import build_dataclass


@pytest.fixture(autouse=True)
def fresh_notes():
    """Each test sees every note once (they are shown once per process)."""
    import agents.common.names as names

    names._noted.clear()
    yield
    names._noted.clear()


def renamed():
    """Expect a note, whether or not this test has seen the name before."""
    import agents.common.names as names

    names._noted.clear()
    return pytest.warns(RenamedWarning)


def test_each_built_in_has_one_name_in_registry_class_and_spec():
    classes = {"dispatcher": DispatcherController, "planner": PlannerController,
               "guard": GuardController, "lookahead": LookaheadController}
    for name, cls in classes.items():
        assert BUILTIN[name].endswith(":" + cls.__name__)
        assert cls.name == name
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a new name gives no note
            assert type(make_controller(name)) is cls
    assert not set(RENAMED_AGENTS) & set(BUILTIN)


@pytest.mark.parametrize("old, new", [
    ("heuristic", "dispatcher"), ("rollout", "planner"), ("handback", "lookahead"),
    ("heuristic[holding=false]", "dispatcher[holding=false]"),
    ("handback[base=fcfs,reward_margin=10]", "lookahead[proposer=fcfs,reward_margin=10]"),
    ("guard[base=rollout,fleet=heuristic[arrival_priority_pct=40],samples=2]",
     "guard[proposer=planner,rollout_policy=dispatcher[arrival_priority_pct=40],samples=2]"),
    ("rollout[base=fcfs]", "planner[rollout_policy=fcfs]"),
])
def test_old_specs_read_as_new_ones(old, new):
    assert canonical_spec(old, note=False) == new
    assert canonical_spec(new, note=False) == new  # a new spec is left as written
    with pytest.warns(RenamedWarning, match="is now"):
        assert type(make_controller(old)) is type(make_controller(new))


def test_specs_without_old_names_are_untouched():
    for spec in ("fcfs", "gcn", "a.pt+b.pt", "runs/x/model_9.pt", "pkg.mod:Cls[a=1, b=x]",
                 "dispatcher[holding = false]", "guard[proposer=gcn]"):
        assert canonical_spec(spec, note=False) == spec


def test_old_class_and_argument_names_still_work():
    assert GuardedController is GuardController and RolloutPlanner is PlannerController
    assert HandbackController is LookaheadController
    with pytest.warns(RenamedWarning, match="'fleet' is now 'rollout_policy'"):
        guard = GuardController(base="fcfs", fleet="heuristic", defer_pct=30)
    assert type(guard.own_rollout_policy) is DispatcherController
    with pytest.warns(RenamedWarning):
        assert guard.base is guard.proposer
    with pytest.raises(TypeError, match="given twice"):
        GuardController(proposer="fcfs", base="fcfs")
    with pytest.warns(RenamedWarning):
        planner = PlannerController(base=DispatcherController())
    assert type(planner.rollout_policy) is DispatcherController


def test_the_note_is_one_line_and_once_per_name():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        canonical_spec("heuristic")
        canonical_spec("heuristic")
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert str(caught[0].message) == "agent 'heuristic' is now 'dispatcher' (the old name still works)"


def test_evaluation_suites_sweeps_and_train_configs_read_old_names(tmp_path):
    with renamed():
        assert EvalSettings(agents=("heuristic", "handback")).agents == ("dispatcher", "lookahead")
    suite = tmp_path / "suite.yaml"
    suite.write_text("name: mine\nconfigs: [paper]\nagents: [gcn, heuristic]\n")
    with renamed():
        assert load_suite(suite).agents == ("gcn", "dispatcher")
    with renamed():
        assert parse_sweep({"agents": ["rollout", "fcfs"], "grid": {"uncertainty.wind_gust_prob": [0, 0.1]}},
                           "s", "s.yaml").agents == (
            "planner", "fcfs")
    old = tmp_path / "old.yaml"
    old.write_text("pretrain:\n  teacher: guarded_rollout\n  rollout_horizon: 7\n"
                   "  rollout_rescue: true\nevaluation:\n  agents: [random, heuristic]\n")
    with renamed():
        cfg = load_train_config(old)
    assert cfg.pretrain.teacher == "guarded_planner" and cfg.pretrain.planner_horizon == 7
    assert cfg.pretrain.planner_rescue and cfg.evaluation.agents == ("random", "dispatcher")
    from agents.training.config import TrainConfig

    with pytest.raises(ValueError, match="rollout_horizon: the old name of pretrain.planner_horizon"):
        build_dataclass(TrainConfig, {"pretrain": {"rollout_horizon": 4, "planner_horizon": 4}})


def test_paired_reads_old_and_new_names_on_older_files(tmp_path, capsys):
    path = tmp_path / "episodes.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(paired.NEEDED)
        for seed in range(5):
            writer.writerow(["heuristic", "paper", seed, 100 + seed, 0, 0, 0])
            writer.writerow(["handback", "paper", seed, 110 + seed, 0, 0, 0])
    assert set(paired.read_episodes([path])) == {"dispatcher", "lookahead"}
    assert paired.main([str(path), "--pair", "dispatcher", "lookahead"]) == 0
    new = capsys.readouterr().out
    with renamed():
        assert paired.main([str(path), "--pair", "heuristic", "handback",
                            "--reference", "heuristic"]) == 0
    old = capsys.readouterr().out
    assert "dispatcher → lookahead" in new and "dispatcher → lookahead" in old
