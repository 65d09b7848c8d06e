"""Controllers: legality over full days, FCFS's rules on hand-built situations, and the
ordering random < FCFS < heuristic on fixed seeds."""

import numpy as np
import pytest

from agents.controllers.base import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, TAXIING, Observation,
)
from agents.controllers.episode import run_aec_episode, run_gym_episode
from agents.controllers.fcfs import FCFSController
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.registry import AgentSpecError, make_controller
from agents.common.seeds import EVAL_SEEDS
from marl_vertiport import vertiport_v1
from marl_vertiport.gym_env import VertiportEnv
from marl_vertiport.sim.schema import EVTOL_FEATURES

COL = {name: i for i, name in enumerate(EVTOL_FEATURES)}
# Default layout: nodes 0-1 normal ports, 2 the charging port, 3-9 hover spots.
NODE_TYPES = [0, 0, 1, 2, 2, 2, 2, 2, 2, 2]
STAY, TAKEOFF, CONTINUE = 0, 1, 12


def make_obs(vehicles: list[dict], me: int, free_nodes: set[int]) -> dict:
    """A hand-built observation: ``vehicles`` give status, battery and minutes_to_schedule."""
    evtols = np.zeros((len(vehicles), len(EVTOL_FEATURES)), dtype=np.float32)
    for i, v in enumerate(vehicles):
        evtols[i, COL["status"]] = v["status"]
        evtols[i, COL["battery_pct"]] = v.get("battery", 100.0)
        evtols[i, COL["minutes_to_schedule"]] = v.get("to_go", 0.0)
    evtols[me, COL["is_self"]] = 1.0
    ports = np.zeros((10, 4), dtype=np.float32)
    ports[:, 1] = NODE_TYPES
    ports[list(free_nodes), 0] = 1.0
    mask = np.zeros(14, dtype=np.int8)
    status = vehicles[me]["status"]
    if status in (ON_PORT, ON_CHARGER):
        mask[[STAY, TAKEOFF]] = 1
        mask[[2 + k for k in free_nodes if k < 3]] = 1
    elif status == HOVERING:
        mask[STAY] = 1
        mask[[2 + k for k in free_nodes]] = 1
    else:
        mask[CONTINUE] = 1
    return {"observation": {"evtol_nodes": evtols, "port_nodes": ports}, "action_mask": mask}


def test_fcfs_lands_in_arrival_order_and_skips_the_rest():
    fcfs = FCFSController()
    # evtol_2 arrived first (seen hovering on an earlier turn), evtol_0 later.
    fcfs.act(make_obs([{"status": AWAY}, {"status": AWAY}, {"status": HOVERING}], 2, {2}))
    fleet = [{"status": HOVERING}, {"status": AWAY}, {"status": HOVERING}]
    # evtol_0 is not at the head: skipped even though the charger is free.
    assert fcfs.act(make_obs(fleet, 0, {2, 5})) == STAY
    # evtol_2 is at the head: lands, preferring the free charging port (node 2 -> action 4).
    assert fcfs.act(make_obs(fleet, 2, {0, 2})) == 4
    # No charger free: a free normal port (node 1 -> action 3).
    assert fcfs.act(make_obs(fleet, 2, {1})) == 3
    # Once evtol_2 is taxiing in, evtol_0 heads the queue.
    fleet[2] = {"status": TAXIING}
    assert fcfs.act(make_obs(fleet, 0, {0})) == 2


def test_fcfs_sixty_percent_rule():
    fcfs = FCFSController()
    # Take-off time has come but only 55 %: no request; it moves to the free charger.
    low = [{"status": ON_PORT, "battery": 55.0, "to_go": -1}]
    assert fcfs.act(make_obs(low, 0, {2})) == 4
    # On the charger still below 60 %: it charges.
    charging = [{"status": ON_CHARGER, "battery": 59.0, "to_go": -2}]
    assert fcfs.act(make_obs(charging, 0, set())) == STAY
    # At 60 % with its time come it requests, heads the queue and takes off.
    ready = [{"status": ON_CHARGER, "battery": 60.0, "to_go": -3}]
    assert fcfs.act(make_obs(ready, 0, set())) == TAKEOFF


def test_fcfs_takeoff_queue_in_request_order():
    fcfs = FCFSController()
    # evtol_1 requests first (its time came first); evtol_0's time comes later.
    fcfs.act(make_obs([{"status": ON_PORT, "to_go": 4}, {"status": ON_PORT, "to_go": 0}], 1, set()))
    both = [{"status": ON_PORT, "to_go": 0}, {"status": ON_PORT, "to_go": -4}]
    assert fcfs.act(make_obs(both, 0, set())) == STAY       # behind evtol_1: skipped
    assert fcfs.act(make_obs(both, 1, set())) == TAKEOFF    # head of the queue
    # Not yet its time: no request, it waits.
    assert FCFSController().act(make_obs([{"status": ON_PORT, "to_go": 3}], 0, set())) == STAY


def test_heuristic_avoids_flagged_conflicts_and_uses_the_charger():
    ctl = DispatcherController()
    obs = make_obs([{"status": TAXIING}, {"status": TAXIING}], 0, set())
    obs["action_mask"][13] = 1
    assert ctl.act(obs) == CONTINUE
    obs["observation"]["evtol_nodes"][:, COL["conflict"]] = 1.0
    assert ctl.act(obs) == 13  # avoid collision
    hovering = make_obs([{"status": HOVERING, "battery": 60.0, "to_go": 10}], 0, {0, 2})
    assert ctl.act(hovering) == 4  # lands on the charger rather than a normal port


def _hold_obs(batteries: list[float], statuses: list[int], free_nodes: set[int],
              nodes: list[int]) -> dict:
    """A hand-built observation on the paper's real layout (node positions from the env) for
    the dispatcher's holding rules: vehicle 0 acts; ``nodes`` gives each vehicle's node."""
    env = vertiport_v1.env(config="paper")
    env.reset(seed=0)
    positions = env.unwrapped.sim.port_features()[:, 2:]
    env.close()
    obs = make_obs([{"status": s, "battery": b} for s, b in zip(statuses, batteries)], 0, free_nodes)
    obs["observation"]["port_nodes"][:, 2:] = positions
    obs["observation"]["evtol_nodes"][:, COL["node"]] = nodes
    xy = positions[nodes]
    obs["observation"]["evtol_nodes"][:, COL["x_m"]:COL["y_m"] + 1] = xy
    return obs


def test_dispatcher_holds_beside_the_charger_and_lets_the_neediest_land():
    ctl, plain = DispatcherController(), DispatcherController(holding=False)
    # Charger (node 2, at (0, 8)) taken, hover spots 3 and 8 free: from spot 9 it moves to
    # spot 3, the one nearer to the charger (action 5), where the earlier dispatcher stays.
    holding = _hold_obs([60.0, 90.0], [HOVERING, ON_CHARGER], {3, 8}, [9, 2])
    assert ctl.holding_spot(Observation(holding)) == 3
    assert ctl.act(holding) == 2 + 3
    assert plain.act(holding) == STAY
    # Beside the charger (spot 4) it keeps moving, to the free spot 3, never to its own.
    at_spot = _hold_obs([60.0, 90.0], [HOVERING, ON_CHARGER], {3}, [4, 2])
    assert ctl.act(at_spot) == 2 + 3
    # Charger free, but another vehicle waits with 30 %: the 60 % one yields and holds on.
    yields = _hold_obs([60.0, 30.0], [HOVERING, HOVERING], {2, 3}, [9, 8])
    assert ctl.act(yields) == 2 + 3
    assert plain.act(yields) == 4  # first come, first served
    # Within the priority margin (58 % against 60 %) it takes the charger (action 4).
    close = _hold_obs([60.0, 58.0], [HOVERING, HOVERING], {2, 3}, [9, 8])
    assert ctl.act(close) == 4
    # The ATC rules waiting out (stay masked: landings only): it lands, on the free normal
    # port, rather than hold; the plain dispatcher makes the same landing.
    forced = _hold_obs([12.0, 90.0], [HOVERING, ON_CHARGER], {0, 3}, [9, 2])
    forced["action_mask"][[STAY, 2 + 3]] = 0
    assert ctl.act(forced) == 2 == plain.act(forced)


def test_holding_moves_keep_clear_of_the_ports():
    # From hover spot 4 (beside the charger), spot 5 is the next nearest to the charger, but
    # the straight path between them passes within 4 m of the charging port: it goes to spot
    # 3, whose path keeps clear (or stays if there is no such spot).
    env = vertiport_v1.env(config="paper")
    env.reset(seed=0)
    xy = env.unwrapped.sim.port_features()[:, 2:]
    env.close()
    a, b, charger = xy[4], xy[5], xy[2]
    t = np.clip((charger - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    assert np.linalg.norm(charger - (a + t * (b - a))) < 4.0  # the premise of this test
    obs = _hold_obs([60.0, 90.0], [HOVERING, ON_CHARGER], {3, 5}, [4, 2])
    assert DispatcherController().act(obs) == 2 + 3
    assert DispatcherController(port_clearance_m=0.0).act(obs) == 2 + 5
    only_close = _hold_obs([60.0, 90.0], [HOVERING, ON_CHARGER], {5}, [4, 2])
    assert DispatcherController().act(only_close) == STAY


def test_remembered_holding_spots_are_the_computed_ones():
    """The dispatcher's memo of holding spots answers as computing afresh does, on every
    hovering observation of busy days on two layouts, asked twice each."""
    ctl, asked = DispatcherController(), 0
    for config, seed in (("paper", 3), ("wide", 4)):
        env = VertiportEnv(config)
        obs, _ = env.reset(seed=seed)
        for _ in range(1440):
            view = Observation(obs)
            if view.status == HOVERING:
                fresh = DispatcherController()._holding_spot(view)
                assert ctl.holding_spot(view) == fresh and ctl.holding_spot(view) == fresh
                asked += 1
            obs, *_ = env.step(ctl.act(obs))
        env.close()
    assert asked > 50 and 0 < len(ctl._holding_memo) < asked


def test_dispatcher_counts_holding_vehicles_as_waiting_for_the_charger():
    # A full vehicle on the charger, inside its window, with a vehicle moving between hover
    # spots: the plain dispatcher does not see it waiting, the holding one does and releases.
    fleet = [ON_CHARGER, TAXIING]
    obs = _hold_obs([100.0, 40.0], fleet, set(), [2, 5])
    obs["observation"]["evtol_nodes"][0, COL["minutes_to_schedule"]] = 4.0
    obs["observation"]["evtol_nodes"][1, COL["node"]] = 5  # bound for hover spot 5
    assert DispatcherController()._charger_wanted(Observation(obs))
    assert not DispatcherController(holding=False)._charger_wanted(Observation(obs))


def test_bound_dispatcher_takes_off_on_what_a_trip_needs_not_a_fixed_90_percent():
    env = vertiport_v1.env(config="paper")
    sim = env.unwrapped.sim
    d = DispatcherController()
    d.bind(sim)
    cfg = sim.cfg
    need = (sim.energy.trip_pct.max(axis=1) + cfg.atc.energy_reserve_pct
            + 2 * sim.n * cfg.battery.hover_drain_pct)  # two turns of hovering on return
    assert np.allclose(d._takeoff_need_pct, np.minimum(need, 90.0))
    assert d._takeoff_need_pct.max() < 50.0  # calibrated trips cost 10-20 %
    assert d.cruise_drain_pct_per_m == 0.125
    # At the start of a day, a vehicle on a normal port that idled into its window at 60 %
    # takes off; unbound (a take-off needs 90 %) it would stay and idle on.
    env.reset(seed=800000)
    obs = env.observe(env.agent_selection)
    rows = obs["observation"]["evtol_nodes"]
    me = int(np.argmax(rows[:, COL["is_self"]]))
    assert rows[me, COL["status"]] == ON_PORT and obs["action_mask"][1]  # this day's evtol_0
    rows = rows.copy()
    rows[me, COL["battery_pct"]] = 60.0
    rows[me, COL["minutes_to_schedule"]] = 0.0
    obs = {"observation": dict(obs["observation"], evtol_nodes=rows),
           "action_mask": obs["action_mask"]}
    assert d.act(obs) == 1
    assert DispatcherController().act(obs) != 1
    env.close()


def _bound_with_and_without(**option) -> tuple[DispatcherController, DispatcherController]:
    """A dispatcher with ``option`` and one with the defaults, both bound to ``paper``."""
    env = vertiport_v1.env(config="paper")
    pair = DispatcherController(**option), DispatcherController()
    for d in pair:
        d.bind(env.unwrapped.sim)
    env.close()
    return pair


def test_departures_first_option_lets_a_ready_departure_from_a_normal_port_go_first():
    d, default = _bound_with_and_without(yield_margin_pct=20.0)
    need = float(d._takeoff_need_pct.max())

    def hovering(battery, to_go=10.0, other_battery=80.0, other_to_go=0.0):
        # Vehicle 0 hovers at spot 9 with the charger (node 2) free; vehicle 1 is on normal
        # port 0, charged ``other_battery``, its take-off ``other_to_go`` minutes away.
        obs = _hold_obs([battery, other_battery], [HOVERING, ON_PORT], {2, 3}, [9, 0])
        obs["observation"]["evtol_nodes"][:, COL["minutes_to_schedule"]] = [to_go, other_to_go]
        return obs

    # A turn of hovering (two vehicles in this observation: 2 minutes, 4 %) and the margin, to
    # spare.
    full = need + 20.0 + 4.0 + 1.0
    assert d.act(hovering(full)) == STAY  # the departure goes first
    assert default.act(hovering(full)) == 4  # off by default: it lands on the charger
    assert d.act(hovering(full, other_to_go=30.0)) == 4  # none due
    short = float(d._takeoff_need_pct[0]) - 1.0  # what a take-off from port 0 needs, less 1
    assert d.act(hovering(full, other_battery=short)) == 4  # not charged for its trip
    assert d.act(hovering(full - 2.0)) == 4  # too little to spare
    assert d.act(hovering(full, to_go=-4.0)) == 4  # its landing would be late at its next turn
    assert DispatcherController(yield_margin_pct=20.0).act(hovering(full)) == 4  # unbound


def test_departure_hold_option_raises_a_take_off_need_on_the_charger_per_departing_vehicle():
    d, default = _bound_with_and_without(departure_hold_min=5.0)
    obs = _hold_obs([60.0, 90.0, 90.0], [ON_CHARGER, DEPARTING, DEPARTING], set(), [2, 0, 1])
    base = default._takeoff_need(Observation(obs))
    assert base == float(d._takeoff_need_pct[2])
    # Two others departing: 5 minutes of hovering (2 %/min) more for each.
    assert d._takeoff_need(Observation(obs)) == pytest.approx(base + 2 * 5 * 2.0)
    on_port = _hold_obs([60.0, 90.0, 90.0], [ON_PORT, DEPARTING, DEPARTING], set(), [0, 1, 2])
    assert d._takeoff_need(Observation(on_port)) == float(d._takeoff_need_pct[0])  # chargers only


def test_low_arrivals_first_option_yields_the_charger_to_a_low_vehicle_still_arriving():
    # Vehicle 0 hovers at spot 9 with 69 %, the charger (node 2) and spot 3 free; vehicle 1
    # arrives (bound for spot 8) with ``arriving`` %.
    def arrival(arriving):
        return _hold_obs([69.0, arriving], [HOVERING, ARRIVING], {2, 3}, [9, 8])

    option, default = DispatcherController(arrival_priority_pct=40.0), DispatcherController()
    assert default.act(arrival(32.0)) == 4  # off by default: it lands on the charger
    assert option.act(arrival(32.0)) == 2 + 3  # it holds beside the charger instead
    assert option.act(arrival(45.0)) == 4  # not low enough to be given the charger
    assert option.act(_hold_obs([35.0, 32.0], [HOVERING, ARRIVING], {2, 3}, [9, 8])) == 4
    # Within the priority margin (35 % against 32 %) the hovering vehicle keeps its turn.
    plain = DispatcherController(holding=False, arrival_priority_pct=40.0)
    assert plain.act(arrival(32.0)) == 4  # without the holding pattern, no priority at all


def test_bound_dispatcher_counts_turns_in_minutes_where_the_atc_decides_twice_a_minute():
    env = vertiport_v1.env(config="wide")  # 8 eVTOLs, half-minute steps
    d = DispatcherController()
    d.bind(env.unwrapped.sim)
    assert d.minutes_per_step == 0.5
    assert d.hover_drain_pct_per_min == 2.0 and d.ground_idle_drain_pct_per_min == 4.0
    env.reset(seed=800000)
    obs = Observation(env.observe(env.agent_selection))
    assert d._turn_gap(obs) == 4.0  # 8 turns of half a minute
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
@pytest.mark.parametrize("name", ["fcfs", "dispatcher"])
def test_full_days_with_only_legal_actions(config, name):
    env = vertiport_v1.env(config=config)
    metrics = run_aec_episode(env, make_controller(name), EVAL_SEEDS[0])  # raises if illegal
    assert metrics["steps"] == 1440 and metrics["completed_trips"] >= 1


@pytest.mark.slow
def test_ordering_random_fcfs_heuristic_on_fixed_seeds():
    seeds = EVAL_SEEDS[900:903]
    means = {}
    for name in ("random", "fcfs", "dispatcher"):
        rewards = []
        for config in ("paper", "paper_uncertain"):
            env = vertiport_v1.env(config=config)
            rewards += [run_aec_episode(env, make_controller(name), s)["total_reward"] for s in seeds]
        means[name] = np.mean(rewards)
    assert means["random"] < means["fcfs"] < means["dispatcher"], means


def test_the_same_controller_runs_through_both_apis():
    aec = run_aec_episode(vertiport_v1.env(config="paper", **{"schedule.episode_steps": 200}),
                          make_controller("dispatcher"), 5)
    gym = run_gym_episode(VertiportEnv(config="paper", **{"schedule.episode_steps": 200}),
                          make_controller("dispatcher"), 5)
    assert aec == gym


def test_illegal_action_from_a_controller_is_named():
    class Stubborn:
        name = "stubborn"

        def act(self, observation):
            return 13  # avoid collision: illegal for a parked vehicle

    env = vertiport_v1.env()
    with pytest.raises(ValueError, match=r"'stubborn' returned the illegal action 13 for evtol_0"):
        run_aec_episode(env, Stubborn(), 0)


@pytest.mark.parametrize("spec, message", [
    ("fcsf", "unknown agent 'fcsf'"),
    ("no_such_module:Thing", "cannot import module 'no_such_module'"),
    ("agents.controllers.fcfs:NoSuchClass", "has no attribute 'NoSuchClass'"),
    ("agents.common.seeds:EVAL_SEED_BASE", "has no act"),
])
def test_bad_agent_specs(spec, message):
    with pytest.raises(AgentSpecError, match=message):
        make_controller(spec)


def test_custom_agent_example_runs(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "examples/custom_agent.py", "1"], cwd=root,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "one day:" in out.stdout and "ChargeFirst" in out.stdout
    assert (root / "runs" / "eval_custom" / "results.json").exists()


def test_the_controller_example_of_docs_controllers_md_plays_a_legal_day():
    """The example a newcomer copies runs: its code block, one day of the paper's case 2."""
    import re as _re
    from pathlib import Path as _Path

    from agents.controllers.episode import run_aec_episode
    from marl_vertiport import vertiport_v1

    text = (_Path(__file__).resolve().parents[2] / "docs" / "controllers.md").read_text()
    (code,) = [block for block in _re.findall(r"```python\n(.*?)```", text, _re.S)
               if "class LandOnChargerFirst" in block]
    namespace: dict = {}
    exec(compile(code, "docs/controllers.md", "exec"), namespace)
    metrics = run_aec_episode(vertiport_v1.env(config="paper_uncertain"),
                              namespace["LandOnChargerFirst"](), seed=3)
    assert metrics["steps"] == 1440


def test_pyg_example_acts_legally_on_two_vertiports_through_to_graph_batch():
    """examples/pyg_policy.py: torch-geometric layers on marl_vertiport.graph's batches, one set
    of weights on the paper's vertiport and on mid (2 hours of each)."""
    import torch

    from agents.controllers.episode import run_aec_episode
    from examples.pyg_policy import PygController, PygPolicy
    from marl_vertiport import vertiport_v1
    from marl_vertiport.graph import to_graph_batch

    for config in ("paper", "mid"):
        env = vertiport_v1.env(config=config, schedule__episode_steps=120)
        metrics = run_aec_episode(env, PygController(), seed=0)  # illegal actions would raise
        assert metrics["steps"] == 120
        env.reset(seed=1)
        obs = [env.observe(a) for a in env.agents]
        logits = PygPolicy()(obs)
        legal = torch.as_tensor(np.stack([o["action_mask"] for o in obs])).bool()
        assert logits.shape == legal.shape and torch.isinf(logits[~legal]).all()
        assert torch.isfinite(logits[legal]).all()
        assert to_graph_batch(obs).num_graphs == len(obs)


def test_every_illegal_action_message_lists_the_legal_actions_one_way():
    """The env's three refusals (wrong type, out of range, masked out) and the evaluation's
    check of a controller list the legal actions alike: ``index (name)``, comma-separated."""
    env = vertiport_v1.env()
    env.reset(seed=0)
    obs = env.observe(env.agent_selection)
    sim = env.unwrapped.sim
    names = sim.actions.names(sim.layout)
    legal = ", ".join(f"{i} ({names[i]})" for i in np.flatnonzero(obs["action_mask"]))
    illegal = int(np.flatnonzero(obs["action_mask"] == 0)[0])
    messages = []
    for action in ("stay", 99, illegal):
        with pytest.raises(ValueError) as exc:
            env.step(action)
        messages.append(str(exc.value))

    class Stubborn:
        name = "stubborn"

        def act(self, observation):
            return illegal

    with pytest.raises(ValueError) as exc:
        run_aec_episode(vertiport_v1.env(), Stubborn(), 0)
    messages.append(str(exc.value))
    assert all(m.endswith(legal) for m in messages), messages
    assert "[" not in legal and "'" not in legal
