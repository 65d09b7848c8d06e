"""`lookahead`: the shipped policy inside the look-ahead with the `lookahead` preset, one name
for the learned ATC, its proposer a parameter, recorded in results as playing the checkpoint it
wraps; the settings dataclass and its presets."""

from pathlib import Path

import pytest
from helpers import guarded_actions

from agents.common.specs import checkpoint_files
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.fcfs import FCFSController
from agents.controllers.gcn import GCNController
from agents.controllers.guard import GuardController
from agents.controllers.lookahead import LookaheadController
from agents.controllers.lookahead_settings import PRESETS, LookaheadSettings
from agents.controllers.registry import SHIPPED_CHECKPOINT, make_controller
from marl_vertiport import vertiport_v1


def test_lookahead_is_the_guard_around_the_shipped_policy_with_its_preset():
    controller = make_controller("lookahead")
    assert isinstance(controller, LookaheadController) and controller.name == "lookahead"
    assert isinstance(controller.proposer, GCNController)
    assert controller.proposer.path == SHIPPED_CHECKPOINT
    assert isinstance(controller.own_rollout_policy, DispatcherController)
    assert controller.settings == PRESETS["lookahead"]
    s = controller.settings
    assert (s.defer_pct, s.margin_pct, s.quiet_pct, s.reward_margin) == (30, 25, 101, 0.0)
    assert make_controller("lookahead[reward_margin=null]").settings.reward_margin is None
    assert make_controller("lookahead[reward_margin=10]").settings.reward_margin == 10.0
    assert controller.onward is None
    changed = make_controller("lookahead[self_check=true,defer_pct=40]")
    assert changed.onward.policy.name.endswith(":fast") and changed.onward.defer_pct == 40
    assert changed.settings.defer_pct == 40 and changed.settings.margin_pct == 25
    with pytest.raises(ValueError, match="margin_pct"):
        make_controller("lookahead[margin_pct=120]")


def test_the_proposer_is_a_parameter():
    """FCFS where the policy was: the control of what learning adds to the search."""
    controller = make_controller("lookahead[proposer=fcfs]")
    assert isinstance(controller.proposer, FCFSController)
    assert isinstance(controller.own_rollout_policy, DispatcherController)
    assert controller.settings == PRESETS["lookahead"]
    assert isinstance(LookaheadController(proposer="dispatcher").proposer, DispatcherController)


def test_lookahead_decides_as_the_guard_spelled_out():
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 90})
    spelled = GuardController(proposer="gcn", rollout_policy="dispatcher",
                              settings=LookaheadSettings(defer_pct=30.0, margin_pct=25.0,
                                                         quiet_pct=101.0, reward_margin=0.0))
    named = make_controller("lookahead")
    assert guarded_actions(env, named, seed=4) == guarded_actions(env, spelled, seed=4)
    assert named.checks > 0
    named.close()
    spelled.close()
    env.close()


def test_settings_are_checked_when_made_and_name_what_is_wrong():
    assert LookaheadSettings.preset("guard") == LookaheadSettings()
    with pytest.raises(ValueError, match="preset 'nope'"):
        LookaheadSettings.preset("nope")
    for bad, match in [({"horizon_min": 0}, "horizon_min"), ({"samples": 0}, "samples"),
                       ({"compare_samples": 2}, "compare_samples"), ({"prefer": "x"}, "prefer"),
                       ({"floor_pct": 101}, "floor_pct"),
                       ({"clairvoyant": True, "nominal": True}, "clairvoyant")]:
        with pytest.raises(ValueError, match=match):
            LookaheadSettings(**bad)
    with pytest.raises(TypeError, match="'no_such'"):
        LookaheadSettings().replace(no_such=1)
    assert LookaheadSettings().replace(samples=8).samples == 8
    # A setting that hands decisions over needs a rollout policy of its own.
    with pytest.raises(ValueError, match="defer_pct .* rollout_policy"):
        GuardController(defer_pct=30)
    with pytest.raises(ValueError, match="self_check .* rollout_policy"):
        GuardController(self_check=True)
    guard = GuardController(settings="lookahead", rollout_policy="dispatcher", samples=2)
    assert guard.settings == PRESETS["lookahead"].replace(samples=2)


def test_results_record_the_checkpoint_a_look_ahead_plays():
    assert checkpoint_files("lookahead") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("lookahead[proposer=runs/x/model_9.pt,defer_pct=40]") == [
        Path("runs/x/model_9.pt")]
    assert checkpoint_files("lookahead[proposer=fcfs]") == []
    assert checkpoint_files("guard[proposer=gcn,rollout_policy=dispatcher]") == [
        SHIPPED_CHECKPOINT]
    assert checkpoint_files("guard[proposer=a.pt+b.pt,rollout_policy=dispatcher]") == [
        Path("a.pt"), Path("b.pt")]
    assert checkpoint_files("guard") == [] and checkpoint_files("guard[proposer=fcfs]") == []
    # Records made before 0.2.0 name the same checkpoints under the old names.
    assert checkpoint_files("handback") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("guard[base=gcn,fleet=heuristic]") == [SHIPPED_CHECKPOINT]
