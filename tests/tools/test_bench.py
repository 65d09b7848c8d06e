"""The benchmark on a tiny budget: it runs end to end and reports every field (no timing is
asserted)."""

import json

from agents.bench import main


def test_bench_smoke(tmp_path):
    report = tmp_path / "performance.md"
    assert main(["--steps", "200", "--repeats", "2", "--configs", "paper", "large",
                 "--traffic-days", "1", "--check-days", "1", "--check-repeats", "2",
                 "--planner-decisions", "5",
                 "--vector-steps", "10", "--copies", "2", "--train-iterations", "1",
                 "--out", str(tmp_path), "--report", str(report)]) == 0
    data = json.loads((tmp_path / "bench.json").read_text())
    assert {(r["api"], r["config"]) for r in data["env"]} == {
        ("aec", "paper"), ("single_agent", "paper"), ("aec", "large"), ("single_agent", "large")}
    for row in data["env"]:
        assert row["steps_per_s_min"] <= row["steps_per_s_median"] <= row["steps_per_s_max"]
        assert row["engine_us_per_step"] > 0 and row["overhead_ratio"] > 0
        assert row["engine_alone_us_per_step"] > 0 and row["overhead_ratio_engine_alone"] > 0
        assert row["moving_overhead_ratio"] > 0 and 0 < row["moving_fraction"] <= 1
    assert {(r["workload"], r["config"]) for r in data["traffic"]} == {
        ("dispatcher", "paper"), ("fcfs", "paper"), ("dispatcher", "large"), ("fcfs", "large")}
    for row in data["traffic"]:
        assert row["steps"] > 0 and row["days"] == 1
        assert row["steps_per_s_min"] <= row["steps_per_s_median"] <= row["steps_per_s_max"]
        assert row["engine_alone_us_per_step"] > 0 and 0 < row["moving_fraction"] <= 1
    check = data["separation_check"]
    assert check["days"] == 1 and check["repeats"] == 2
    assert check["on_steps_per_s"] > 0 and check["off_steps_per_s"] > 0
    low, high = check["pair_cost_quartiles"]
    assert low <= high and abs(check["cost"]) < 1
    assert [r["fleet_size"] for r in data["fleet_sizes"]] == [4, 8, 16, 32]
    assert all(r["us_per_step"] > 0 and r["steps"] > 0 for r in data["fleet_sizes"])
    assert (tmp_path / "performance_fleet.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    planner = data["planner"]
    assert planner["decisions"] == 5 and planner["decisions_per_s"] > 0
    assert 0 < planner["engine_share"] < 1 and planner["overhead_ratio"] > 0
    assert planner["overhead_ratio_engine_alone"] > 0 and 0 <= planner["simulated"] <= 5
    assert data["profile"]["workload"] == "dispatcher" and data["profile"]["steps"] == 1440
    assert data["profile"]["top"] and all(0 <= e["own_share"] <= 1 for e in data["profile"]["top"])
    assert [(r["copies"], r["processes"]) for r in data["vector"]] == [(2, 1), (2, 1), (2, 2)]
    assert [(r["batch"], r["path"]) for r in data["inference"]] == [
        (1, "torch"), (64, "torch"), (1, "numpy")]
    assert data["training"]["env_steps_per_s"] > 0 and data["training"]["peak_memory_mb"] > 0
    assert data["env_peak_memory_mb"] > 0
    assert [r["api"] for r in data["api_floor"]] == ["aec", "single_agent"]
    assert all(r["us_per_step"] > 0 for r in data["api_floor"])
    text = report.read_text()
    assert "overhead / engine alone" in text and "training throughput" in text
    assert "AEC steps/s under the dispatcher's traffic on the paper's vertiport" in text
    assert "Cost against fleet size" in text and "decisions per" in text
    assert "Where a step's time goes (cProfile, AEC API, `paper`, the dispatcher's traffic" in text
    assert "The floor under that ratio" in text and "Against the targets" in text
    for measure in ("AEC steps/s, dispatcher's traffic, `paper`", "overhead / engine in steps "
                    "with motion, `large`", "cost per step, 4 to 32 eVTOLs",
                    "separation check's cost, dispatcher's traffic, `paper`"):
        assert measure in text


def test_api_floor_loop_steps_a_do_nothing_env_through_both_apis():
    from agents.bench.overhead import api_floor_loop

    for api in ("aec", "single_agent"):
        assert api_floor_loop(api, 50) > 0  # runs; its value is only reported, never asserted


def test_engine_replay_repeats_the_recorded_run():
    """The engine-alone measurement replays the pybullet calls of a run of the same seed: the
    recorded run steps the engine exactly as often as a plain run does, and its timed calls
    hold one ``stepSimulation`` per step with motion."""
    from agents.bench.engine import EngineCallRecorder, replay_engine
    from agents.bench.env import env_loop
    from marl_vertiport.sim import physics as physics_module

    plain = env_loop("single_agent", "paper", 300, seed=3)
    real = physics_module.p
    recorder = EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = env_loop("single_agent", "paper", 300, seed=3, recorder=recorder)
    finally:
        physics_module.p = real
    assert recorded["moving_steps"] == plain["moving_steps"] > 0
    timed = recorder.calls[recorded["first_timed_call"]:recorded["last_timed_call"]]
    assert sum(fn is real.stepSimulation for fn, _, _ in timed) == plain["moving_steps"]
    assert replay_engine(recorder, recorded["first_timed_call"], recorded["last_timed_call"]) > 0


def test_planner_engine_replay_follows_both_clients_and_times_only_the_decisions():
    """The planner's engine-alone figure replays the calls on the env's client and on its
    scratch simulator's, each on a fresh client of its own, and times only the decisions'."""
    from agents.bench.engine import EngineCallRecorder, replay_engine_spans
    from agents.bench.planner import planner_loop
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = planner_loop("paper", 40, seed=5, recorder=recorder)
    finally:
        physics_module.p = real
    assert len(recorder.connected) == 2 and len(recorded["spans"]) == 40
    inside = sum(last - first for first, last in recorded["spans"])
    assert 0 < inside < len(recorder.calls)  # the env's own steps lie between the spans
    steps = [fn is real.stepSimulation for fn, _, _ in recorder.calls]
    assert 0 < sum(any(steps[a:b]) for a, b in recorded["spans"]) <= recorded["simulated"]
    assert replay_engine_spans(recorder, recorded["spans"]) > 0


def test_engine_replay_ignores_other_envs_collected_during_the_recording(monkeypatch):
    """An env built elsewhere in the process and garbage-collected while a run is recorded
    disconnects its own client through the recorded module; the replay must not follow it."""
    import gc

    import agents.bench.env as bench
    from marl_vertiport.gym_env import VertiportEnv

    others = [VertiportEnv("paper") for _ in range(2)]
    plain_loop, runs = bench.env_loop, []

    def loop(*args, **kwargs):
        runs.append(1)
        if len(runs) == 2:  # the recorded run
            others.clear()
            gc.collect()
        return plain_loop(*args, **kwargs)

    monkeypatch.setattr(bench, "env_loop", loop)
    result = bench.env_run("aec", "paper", 100, seed=0)
    assert len(runs) == 2 and result["engine_alone_s_per_step"] > 0


def test_floor_paragraph_names_the_binding_api_and_the_room_left():
    from agents.bench.report import _floor_lines

    env_rows = [{"api": "aec", "config": "paper", "engine_us_per_step": 4.0, "engine_us_per_moving_step": 50.0},
                {"api": "single_agent", "config": "paper", "engine_us_per_step": 5.0,
                 "engine_us_per_moving_step": 50.0}]
    floor = {"api_floor": [{"api": "aec", "us_per_step": 10.0}, {"api": "single_agent", "us_per_step": 4.0}]}
    (line,) = _floor_lines(floor, env_rows)
    assert "2.50 times" in line and "cannot come down to 1.0" in line  # AEC: floor above the engine
    assert "0.80 times" in line and "leaves 1.0 µs" in line  # single-agent: room left
    assert "at most 0.20 times" in line
    assert _floor_lines({}, env_rows) == []  # results of an older benchmark: no paragraph


def test_replaying_a_controllers_recorded_actions_reproduces_its_days():
    """The traffic the benchmark replays is the controller's: replayed through the env, the
    recorded actions give the same day, metric for metric."""
    from agents.bench.env import record_traffic
    from agents.controllers.episode import run_aec_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v1

    traffic = record_traffic("dispatcher", "paper_uncertain", days=2, seed=31)
    env = vertiport_v1.env(config="paper_uncertain")
    for d, actions in enumerate(traffic):
        played = run_aec_episode(env, make_controller("dispatcher"), seed=31 + d)

        class Replay:
            def __init__(self):
                self.it = iter(actions)

            def act(self, observation):
                return next(self.it)

        replayed = run_aec_episode(env, Replay(), seed=31 + d)
        assert replayed == played and len(actions) == played["steps"]


def test_compare_times_the_env_of_another_checkout_on_the_same_traffic(tmp_path):
    """agents.bench.compare replays one recorded traffic through the env of each checkout in a
    process of its own; against this very checkout the two sides run the same env."""
    import json

    from agents.bench.compare import main
    from agents.common.provenance import REPO_ROOT

    out = tmp_path / "compare.json"
    assert main(["--base", str(REPO_ROOT), "--days", "1", "--repeats", "1", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["steps"] > 1000 and len(result["runs"]["base"]) == len(result["runs"]["this"]) == 1
    assert result["ratio"] > 0
    assert main(["--base", str(tmp_path)]) == 2  # not a checkout: refused


def test_ecosystem_bench_measures_every_row_and_names_a_missing_extra(tmp_path, monkeypatch):
    from agents.bench import ecosystem

    assert ecosystem.main(["--steps", "60", "--train-steps", "512", "--repeats", "1",
                           "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "ecosystem.json").read_text())
    rows = {r["name"]: r for r in data["rows"]}
    assert set(rows) == set(ecosystem.MEASURES)
    for row in rows.values():
        if "missing" not in row:
            assert row["min_steps_per_s"] <= row["steps_per_s"] <= row["max_steps_per_s"]
            assert row["steps_per_s"] > 0
    monkeypatch.setitem(ecosystem.EXTRA_MODULES, "sb3", "a_module_that_is_not_there")
    row = ecosystem.measure("sb3_maskable_ppo", 10, 1)
    assert row["missing"] == "pip install -e '.[sb3]'" and "steps_per_s" not in row
