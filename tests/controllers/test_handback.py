"""`handback`: the shipped policy inside the guard with the hand-back settings, one name for
the learned ATC, recorded in results as playing the checkpoint it wraps."""

from pathlib import Path

import pytest
from test_guard import _guarded_actions

from agents.common.specs import checkpoint_files
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.gcn import GCNController
from agents.controllers.guard import GuardedController
from agents.controllers.handback import HANDBACK_SETTINGS, HandbackController
from agents.controllers.registry import SHIPPED_CHECKPOINT, make_controller
from marl_vertiport import vertiport_v1


def test_handback_is_the_guard_around_the_shipped_policy_with_its_settings():
    controller = make_controller("handback")
    assert isinstance(controller, HandbackController) and controller.name == "handback"
    assert isinstance(controller.base, GCNController) and controller.base.path == SHIPPED_CHECKPOINT
    assert isinstance(controller.fleet, DispatcherController)
    assert (controller.defer_pct, controller.margin_pct, controller.quiet_pct) == (30, 25, 101)
    assert controller.reward_margin == 0.0  # the rollouts choose between policy and dispatcher
    assert make_controller("handback[reward_margin=null]").reward_margin is None
    assert make_controller("handback[reward_margin=10]").reward_margin == 10.0
    assert controller.onward is None
    changed = make_controller("handback[self_check=true,defer_pct=40]")
    assert changed.onward.policy.name.endswith(":fast") and changed.onward.defer_pct == 40
    assert changed.defer_pct == 40 and changed.margin_pct == 25
    with pytest.raises(ValueError, match="margin_pct"):
        make_controller("handback[margin_pct=120]")


def test_handback_decides_as_the_guard_spelled_out():
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 90})
    spelled = GuardedController(base="gcn", **HANDBACK_SETTINGS)
    named = make_controller("handback")
    assert _guarded_actions(env, named, seed=4) == _guarded_actions(env, spelled, seed=4)
    assert named.checks > 0
    named.close()
    spelled.close()
    env.close()


def test_results_record_the_checkpoint_a_look_ahead_plays():
    assert checkpoint_files("handback") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("handback[base=runs/x/model_9.pt,defer_pct=40]") == [
        Path("runs/x/model_9.pt")]
    assert checkpoint_files("guard[base=gcn,fleet=heuristic]") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("guard[base=a.pt+b.pt,fleet=heuristic]") == [Path("a.pt"), Path("b.pt")]
    assert checkpoint_files("guard") == [] and checkpoint_files("guard[base=fcfs]") == []
