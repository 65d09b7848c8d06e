"""Env steps per second: random legal play (both APIs) and a controller's recorded traffic (the
dispatcher's and FCFS's days replayed through the AEC env), with the engine's share of each
step and the engine alone; the cost of a step against the fleet size, and its figure."""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.bench.engine import EngineCallRecorder, replay_engine

PAPER_STEPS_PER_S = 5.0  # the paper's AirSim simulator: about 0.2 s per step


def record_traffic(agent: str, config: Any, days: int, seed: int) -> list[list[int]]:
    """A controller's actions, day by day (day ``d`` on seed ``seed + d``), through the AEC
    env: the traffic that :func:`env_loop` replays so that only the env is timed."""
    from agents.controllers.episode import run_aec_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env(config=config)
    out = []
    for d in range(days):
        actions: list[int] = []
        run_aec_episode(env, make_controller(agent), seed + d,
                        on_step=lambda _agent, action, _env: actions.append(action))
        out.append(actions)
    env.close()
    return out

def env_loop(api: str, config: str, steps: int, seed: int,
              recorder: EngineCallRecorder | None = None,
              traffic: list[list[int]] | None = None) -> dict[str, float]:
    """``steps`` env steps, timed, one process: random legal actions from ``seed``, or (AEC
    only) the recorded ``traffic`` of :func:`record_traffic` from the same ``seed``, replayed
    day by day (the controller's own cost is then not in the timing).

    With ``recorder`` the engine calls are recorded (and the timings are not representative);
    ``first_timed_call`` is then the index of the first call made inside the timed loop."""
    rng = np.random.default_rng(seed)
    pc = time.perf_counter
    moving_s = moving_engine_s = 0.0
    if traffic is not None and api != "aec":
        raise ValueError("recorded traffic is replayed through the AEC env")
    if api == "aec":
        from marl_vertiport import vertiport_v1

        env = vertiport_v1.env(config=config)
        env.reset(seed=seed)
        physics = env.unwrapped.sim.physics
        physics.engine_seconds, physics.engine_steps = 0.0, 0
        first_call = len(recorder.calls) if recorder else 0
        n = day = k = 0
        start = pc()
        while n < steps:
            for agent in env.agent_iter():
                t, engine, engine_steps = pc(), physics.engine_seconds, physics.engine_steps
                obs, _, term, trunc, _ = env.last()
                if term or trunc:
                    env.step(None)
                    continue
                if traffic is None:
                    legal = np.flatnonzero(obs["action_mask"])
                    env.step(int(legal[rng.integers(legal.size)]))
                else:
                    env.step(traffic[day][k])
                    k += 1
                if physics.engine_steps != engine_steps:
                    moving_s += pc() - t
                    moving_engine_s += physics.engine_seconds - engine
                n += 1
                if n >= steps:
                    break
            else:
                if traffic is None:
                    env.reset(seed=seed + n)
                else:
                    day, k = (day + 1) % len(traffic), 0
                    env.reset(seed=seed + day)
    else:
        from marl_vertiport.gym_env import VertiportEnv

        env = VertiportEnv(config=config)
        obs, _ = env.reset(seed=seed)
        physics = env.sim.physics
        physics.engine_seconds, physics.engine_steps = 0.0, 0
        first_call = len(recorder.calls) if recorder else 0
        start = pc()
        for n in range(steps):
            t, engine, engine_steps = pc(), physics.engine_seconds, physics.engine_steps
            legal = np.flatnonzero(obs["action_mask"])
            obs, _, _, truncated, _ = env.step(int(legal[rng.integers(legal.size)]))
            if truncated:
                obs, _ = env.reset(seed=seed + n)
            if physics.engine_steps != engine_steps:
                moving_s += pc() - t
                moving_engine_s += physics.engine_seconds - engine
        n = steps
    elapsed = pc() - start
    last_call = len(recorder.calls) if recorder else 0
    engine, moving_steps = physics.engine_seconds, physics.engine_steps
    env.close()
    return {"steps": n, "elapsed_s": elapsed, "engine_s": engine, "moving_steps": moving_steps,
            "moving_s": moving_s, "moving_engine_s": moving_engine_s,
            "first_timed_call": first_call, "last_timed_call": last_call}

def env_run(api: str, config: str, steps: int, seed: int,
             traffic: list[list[int]] | None = None) -> dict[str, float]:
    """One timed run of ``steps`` env steps (random legal actions, or replayed ``traffic``),
    and the engine alone replaying the same motion: a second, untimed run of the same seed
    records its pybullet calls, which are then replayed in bare pybullet and timed."""
    run = env_loop(api, config, steps, seed, traffic=traffic)
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = env_loop(api, config, steps, seed, recorder, traffic=traffic)
    finally:
        physics_module.p = real
    alone = replay_engine(recorder, recorded["first_timed_call"], recorded["last_timed_call"])
    n, elapsed, engine = run["steps"], run["elapsed_s"], run["engine_s"]
    moving = run["moving_steps"]
    return {
        "steps_per_s": n / elapsed, "total_s_per_step": elapsed / n,
        "engine_s_per_step": engine / n, "engine_s_per_moving_step": engine / max(moving, 1),
        "moving_fraction": moving / n,
        "overhead_ratio": (elapsed - engine) / max(engine, 1e-12),
        "moving_overhead_ratio": (run["moving_s"] - run["moving_engine_s"])
        / max(run["moving_engine_s"], 1e-12),
        "engine_alone_s_per_step": alone / n,
        "overhead_ratio_engine_alone": (elapsed - alone) / max(alone, 1e-12),
    }

def _summary(case_runs: list[dict[str, float]]) -> dict[str, float]:
    """The row of one measurement from its repeated runs (:func:`env_run`): medians over the
    runs, with the spread of the rate."""
    rate = [run["steps_per_s"] for run in case_runs]

    def median(key: str, scale: float = 1.0) -> float:
        return scale * statistics.median(run[key] for run in case_runs)

    return {
        "steps_per_s_median": statistics.median(rate), "steps_per_s_min": min(rate),
        "steps_per_s_max": max(rate),
        "engine_us_per_step": median("engine_s_per_step", 1e6),
        "engine_us_per_moving_step": median("engine_s_per_moving_step", 1e6),
        "engine_alone_us_per_step": median("engine_alone_s_per_step", 1e6),
        "moving_fraction": median("moving_fraction"),
        "total_us_per_step": median("total_s_per_step", 1e6),
        "overhead_ratio": median("overhead_ratio"),
        "moving_overhead_ratio": median("moving_overhead_ratio"),
        "overhead_ratio_engine_alone": median("overhead_ratio_engine_alone"),
        "times_paper": statistics.median(rate) / PAPER_STEPS_PER_S,
    }

def bench_env(steps: int, repeats: int, configs: list[str]) -> list[dict[str, Any]]:
    """Every (config, API) measurement ``repeats`` times, the repeats interleaved (round ``r``
    runs every measurement once) so that a drift of the machine's speed over the benchmark
    spreads over all measurements instead of biasing the ones that happen to run late."""
    cases = [(config, api) for config in configs for api in ("aec", "single_agent")]
    runs: dict[tuple[str, str], list[dict[str, float]]] = {case: [] for case in cases}
    for r in range(repeats):
        for config, api in cases:
            runs[(config, api)].append(env_run(api, config, steps, seed=1000 * r))
        print(f"  env round {r + 1}/{repeats} done", file=sys.stderr)
    rows = []
    for config, api in cases:
        case_runs = runs[(config, api)]
        rows.append({"api": api, "config": config, "steps": steps, "repeats": repeats,
                     **_summary(case_runs)})
        print(f"  env {api:12s} {config:16s} {rows[-1]['steps_per_s_median']:8.0f} steps/s "
              f"(overhead/engine {rows[-1]['overhead_ratio']:.2f}, in steps with motion "
              f"{rows[-1]['moving_overhead_ratio']:.2f})", file=sys.stderr)
    return rows

def bench_traffic(configs: list[str], agents: list[str], days: int, repeats: int,
                  seed: int = 2000) -> list[dict[str, Any]]:
    """Env steps per second under a controller's traffic: its actions for ``days`` days are
    recorded first, then replayed through the AEC env ``repeats`` times (interleaved over the
    cases), so that only the env is timed; with the engine alone and the overhead ratios, as in
    :func:`bench_env`. Random play strands the fleet within hours and leaves most steps without
    motion; this is the load the env exists for."""
    cases = [(config, agent) for config in configs for agent in agents]
    traffic = {case: record_traffic(case[1], case[0], days, seed) for case in cases}
    runs: dict[tuple[str, str], list[dict[str, float]]] = {case: [] for case in cases}
    for r in range(repeats):
        for case in cases:
            steps = sum(len(day) for day in traffic[case])
            runs[case].append(env_run("aec", case[0], steps, seed, traffic=traffic[case]))
        print(f"  traffic round {r + 1}/{repeats} done", file=sys.stderr)
    rows = []
    for (config, agent) in cases:
        case_runs = runs[(config, agent)]
        rows.append({"workload": agent, "api": "aec", "config": config, "days": days,
                     "repeats": repeats, "steps": sum(len(day) for day in traffic[(config, agent)]),
                     **_summary(case_runs)})
        print(f"  traffic {agent:10s} {config:10s} {rows[-1]['steps_per_s_median']:8.0f} steps/s "
              f"({rows[-1]['moving_fraction']:.0%} of steps with motion)", file=sys.stderr)
    return rows


#: Layouts for the cost against fleet size: (label, config, overrides).
FLEET_SIZES = (("4 eVTOLs (paper)", "paper", {}), ("8 eVTOLs (wide)", "wide", {}),
               ("16 eVTOLs (large)", "large", {}),
               ("32 eVTOLs (fleet40_overloaded layout)", "fleet40_overloaded", {"fleet_size": 32}))


def bench_separation_check(days: int, repeats: int, config: str = "paper",
                           seed: int = 2000) -> dict[str, Any]:
    """AEC steps per second under the dispatcher's traffic with the separation check on (rules
    v1) and off (rules v0's procedures, at v1's energy calibration, so that both sides fly the
    same energy model), ``repeats`` interleaved replays each of its own recorded ``days`` days
    (the check changes what the dispatcher does, so each side replays its own traffic);
    medians and the check's cost ``1 - on / off``."""
    from marl_vertiport.config import load_config, with_rules

    on = load_config(config)
    off = with_rules(on, 0).replace(
        **{"battery.cruise_drain_scale": on.battery.cruise_drain_scale})
    cfgs = {"on": on, "off": off}
    traffic = {k: record_traffic("dispatcher", c, days, seed) for k, c in cfgs.items()}
    rates: dict[str, list[float]] = {"on": [], "off": []}
    for _ in range(repeats):
        for k, cfg in cfgs.items():
            steps = sum(len(day) for day in traffic[k])
            run = env_loop("aec", cfg, steps, seed, traffic=traffic[k])
            rates[k].append(run["steps"] / run["elapsed_s"])
    on, off = statistics.median(rates["on"]), statistics.median(rates["off"])
    # The cost in each interleaved pair of replays (one of each side, back to back): its
    # quartiles say how far one pair may stray from the medians' ratio.
    pairs = sorted(1.0 - a / b for a, b in zip(rates["on"], rates["off"]))
    quartiles = statistics.quantiles(pairs, n=4) if len(pairs) > 1 else pairs * 3
    print(f"  separation check on {on:8.0f} steps/s, off {off:8.0f} steps/s "
          f"(cost {100 * (1 - on / off):.1f} %, pairs' quartiles {100 * quartiles[0]:.1f}-"
          f"{100 * quartiles[2]:.1f} %)", file=sys.stderr)
    return {"config": config, "days": days, "seed": seed, "repeats": repeats,
            "on_steps_per_s": on, "off_steps_per_s": off, "cost": 1.0 - on / off,
            "pair_cost_quartiles": [quartiles[0], quartiles[2]]}


def bench_fleet_sizes(days: int, repeats: int, seed: int = 2200) -> list[dict[str, Any]]:
    """µs per AEC step under the dispatcher's recorded traffic for 4, 8, 16 and 32 eVTOLs."""
    from marl_vertiport.config import load_config

    rows = []
    for label, name, overrides in FLEET_SIZES:
        cfg = load_config(name, **overrides)
        traffic = record_traffic("dispatcher", cfg, days, seed)
        steps = sum(len(day) for day in traffic)
        runs = [env_loop("aec", cfg, steps, seed, traffic=traffic) for _ in range(repeats)]
        per_step = statistics.median(run["elapsed_s"] / run["steps"] for run in runs)
        rows.append({"label": label, "fleet_size": cfg.fleet_size, "steps": steps,
                     "us_per_step": 1e6 * per_step,
                     "moving_fraction": statistics.median(r["moving_steps"] / r["steps"] for r in runs)})
        print(f"  fleet {cfg.fleet_size:3d}: {rows[-1]['us_per_step']:.0f} µs per step", file=sys.stderr)
    return rows

def fleet_size_figure(rows: list[dict[str, Any]], path: Path,
                      provenance: dict[str, Any] | None = None) -> None:
    """µs per step against fleet size, with the line proportional to the fleet through the
    smallest fleet's point for comparison; a PNG at ``path`` (``provenance`` in its
    metadata, agents/common/provenance.py)."""
    from agents.common.provenance import png_metadata

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["fleet_size"] for r in rows]
    us = [r["us_per_step"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
    ax.plot(n, us, "o-", label="measured (dispatcher's traffic, AEC)")
    ax.plot(n, [us[0] * k / n[0] for k in n], "--", color="grey", label="linear in the fleet")
    ax.set_xlabel("eVTOLs")
    ax.set_ylabel("µs per env step")
    ax.set_xticks(n)
    ax.set_ylim(bottom=0)
    ax.legend(frameon=False)
    ax.set_title("Cost of a step against fleet size")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata=png_metadata(provenance) if provenance else None)
    plt.close(fig)
