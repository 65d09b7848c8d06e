"""The look-ahead planner's decisions per second over a day, with the engine's share of them and
the engine alone."""

from __future__ import annotations

import time
from typing import Any

from agents.bench.engine import EngineCallRecorder, replay_engine_spans


class _TimedPlanner:
    """The look-ahead planner as a controller of the episode loop, its own calls timed, with
    the engine's share of them (in the env's and its scratch simulator's pybullet clients)."""

    def __init__(self, planner: Any, recorder: EngineCallRecorder | None) -> None:
        self.planner, self.recorder = planner, recorder
        self.engines: list[Any] = []
        self.spent = self.engine = 0.0
        self.planned = 0
        self.spans: list[tuple[int, int]] = []

    def bind(self, sim: Any) -> None:
        self.planner.bind(sim)
        self.engines = [sim.physics, self.planner._scratch.physics]

    def act(self, obs: dict) -> int:
        recorder, engines = self.recorder, self.engines
        first = len(recorder.calls) if recorder else 0
        before = sum(e.engine_seconds for e in engines)
        start = time.perf_counter()
        action = int(self.planner.act(obs))
        self.spent += time.perf_counter() - start
        self.engine += sum(e.engine_seconds for e in engines) - before
        if recorder:
            self.spans.append((first, len(recorder.calls)))
        self.planned += int(self.planner.last_q != {})
        return action

def planner_loop(config: str, decisions: int, seed: int,
                  recorder: EngineCallRecorder | None = None) -> dict[str, Any]:
    """The look-ahead planner drives the AEC env through ``decisions`` turns (the episode
    loop); only its own calls are timed, with the engine's share of them. With ``recorder``
    the engine calls are recorded and ``spans`` lists the index range of each timed call."""
    from agents.controllers.episode import run_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env(config=config)
    timed = _TimedPlanner(make_controller("planner"), recorder)
    metrics = run_episode(env, timed, seed, max_steps=decisions)
    env.close()
    timed.planner.close()
    return {"decisions": int(metrics["steps"]), "simulated": timed.planned, "seconds": timed.spent,
            "engine_s": timed.engine, "spans": timed.spans}

def bench_planner(config: str, decisions: int, seed: int = 2100) -> dict[str, Any]:
    """Decisions per second of the look-ahead planner (``planner``: a snapshot of the simulator,
    40 steps of the dispatcher per candidate action, a restore), timed over its own calls while
    it drives the AEC env through ``decisions`` turns (1440: a whole day); with the engine's
    share of that time and the engine alone (the same calls recorded in a second run and
    replayed in bare pybullet), as for the env rows."""
    run = planner_loop(config, decisions, seed)
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = planner_loop(config, decisions, seed, recorder)
    finally:
        physics_module.p = real
    alone = replay_engine_spans(recorder, recorded["spans"])
    n, spent, engine = run["decisions"], run["seconds"], run["engine_s"]
    return {"config": config, "decisions": n, "simulated": run["simulated"], "seconds": spent,
            "decisions_per_s": n / max(spent, 1e-12),
            "ms_per_simulated_decision": 1e3 * spent / max(run["simulated"], 1),
            "engine_share": engine / max(spent, 1e-12),
            "overhead_ratio": (spent - engine) / max(engine, 1e-12),
            "overhead_ratio_engine_alone": (spent - alone) / max(alone, 1e-12)}
