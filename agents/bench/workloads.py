"""What the benchmark measures: env steps per second (AEC and single-agent), the engine's
share of each step (record and replay in bare pybullet), a profile, vectorised throughput,
inference latency, training throughput and peak memory. Each function returns plain rows."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np



PAPER_STEPS_PER_S = 5.0  # the paper's AirSim simulator: about 0.2 s per step


class _EngineCallRecorder:
    """Stands in for the pybullet module inside :mod:`marl_vertiport.sim.physics` for one run:
    forwards every call and records it with its arguments, so the run's engine work can be
    replayed in bare pybullet (:func:`_replay_engine`). Only calls on the clients opened during
    the recording are kept, and no disconnection: another env of the process that is
    garbage-collected meanwhile disconnects its own client through the same module, which is not
    this run's work (the replay opens and closes a client of its own)."""

    def __init__(self, module: Any) -> None:
        self._module = module
        self.calls: list[tuple[Any, tuple, dict]] = []
        #: The clients opened during the recording, in the order they were opened.
        self.connected: list[int] = []

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._module, name)
        if not callable(attr) or isinstance(attr, type):  # constants and the error class
            return attr
        calls, connected = self.calls, self.connected
        connect, disconnect = self._module.connect, self._module.disconnect

        def call(*args: Any, **kwargs: Any) -> Any:
            result = attr(*args, **kwargs)
            if attr is connect:
                connected.append(result)
                calls.append((attr, args, kwargs))
            elif attr is not disconnect and kwargs.get("physicsClientId") in connected:
                calls.append((attr, args, kwargs))
            return result

        return call


def record_traffic(agent: str, config: Any, days: int, seed: int) -> list[list[int]]:
    """A controller's actions, day by day (day ``d`` on seed ``seed + d``), through the AEC
    env: the traffic that :func:`_env_loop` replays so that only the env is timed."""
    from agents.controllers.episode import run_aec_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v0

    env = vertiport_v0.env(config=config)
    out = []
    for d in range(days):
        actions: list[int] = []
        run_aec_episode(env, make_controller(agent), seed + d,
                        on_step=lambda _agent, action, _env: actions.append(action))
        out.append(actions)
    env.close()
    return out


def _env_loop(api: str, config: str, steps: int, seed: int,
              recorder: _EngineCallRecorder | None = None,
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
        from marl_vertiport import vertiport_v0

        env = vertiport_v0.env(config=config)
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


def _replay_engine(recorder: _EngineCallRecorder, first_timed: int, last_timed: int) -> float:
    """Replay recorded pybullet calls on fresh clients; seconds taken by the calls of the timed
    loop (``calls[first_timed:last_timed]``), with nothing but a loop around them."""
    return _replay_engine_spans(recorder, [(first_timed, last_timed)])


def _replay_engine_spans(recorder: _EngineCallRecorder, spans: list[tuple[int, int]]) -> float:
    """Replay the recorded pybullet calls in order, each recorded client on a fresh one of its
    own; seconds taken by the calls inside ``spans`` (``(first, last)`` index ranges of
    ``recorder.calls``, in order), each span timed as one block with nothing but a loop
    around its calls."""
    from marl_vertiport.sim import physics as physics_module

    p = physics_module.p
    fresh = {recorded: p.connect(p.DIRECT) for recorded in recorder.connected}
    plan = [(fn, args, dict(kwargs, physicsClientId=fresh[kwargs["physicsClientId"]])
             if "physicsClientId" in kwargs else kwargs)
            for fn, args, kwargs in recorder.calls if fn is not p.connect]
    # Indices of recorder.calls -> indices of plan (the connect calls are not replayed).
    shift, index = 0, []
    for fn, _, _ in recorder.calls:
        index.append(len(index) - shift)
        shift += fn is p.connect
    index.append(len(plan))
    elapsed, done = 0.0, 0
    for first, last in spans:
        first, last = index[first], index[last]
        for fn, args, kwargs in plan[done:first]:  # the world as it was when the span began
            fn(*args, **kwargs)
        block = plan[first:last]
        start = time.perf_counter()
        for fn, args, kwargs in block:
            fn(*args, **kwargs)
        elapsed += time.perf_counter() - start
        done = last
    for client in fresh.values():
        p.disconnect(physicsClientId=client)
    return elapsed


def _env_run(api: str, config: str, steps: int, seed: int,
             traffic: list[list[int]] | None = None) -> dict[str, float]:
    """One timed run of ``steps`` env steps (random legal actions, or replayed ``traffic``),
    and the engine alone replaying the same motion: a second, untimed run of the same seed
    records its pybullet calls, which are then replayed in bare pybullet and timed."""
    run = _env_loop(api, config, steps, seed, traffic=traffic)
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = _EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = _env_loop(api, config, steps, seed, recorder, traffic=traffic)
    finally:
        physics_module.p = real
    alone = _replay_engine(recorder, recorded["first_timed_call"], recorded["last_timed_call"])
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
    """The row of one measurement from its repeated runs (:func:`_env_run`): medians over the
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
            runs[(config, api)].append(_env_run(api, config, steps, seed=1000 * r))
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
            runs[case].append(_env_run("aec", case[0], steps, seed, traffic=traffic[case]))
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


class _TimedPlanner:
    """The look-ahead planner as a controller of the episode loop, its own calls timed, with
    the engine's share of them (in the env's and its scratch simulator's pybullet clients)."""

    def __init__(self, planner: Any, recorder: _EngineCallRecorder | None) -> None:
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


def _planner_loop(config: str, decisions: int, seed: int,
                  recorder: _EngineCallRecorder | None = None) -> dict[str, Any]:
    """The look-ahead planner drives the AEC env through ``decisions`` turns (the episode
    loop); only its own calls are timed, with the engine's share of them. With ``recorder``
    the engine calls are recorded and ``spans`` lists the index range of each timed call."""
    from agents.controllers.episode import run_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v0

    env = vertiport_v0.env(config=config)
    timed = _TimedPlanner(make_controller("rollout"), recorder)
    metrics = run_episode(env, timed, seed, max_steps=decisions)
    env.close()
    timed.planner.close()
    return {"decisions": int(metrics["steps"]), "simulated": timed.planned, "seconds": timed.spent,
            "engine_s": timed.engine, "spans": timed.spans}


def bench_planner(config: str, decisions: int, seed: int = 2100) -> dict[str, Any]:
    """Decisions per second of the look-ahead planner (``rollout``: a snapshot of the simulator,
    40 steps of the dispatcher per candidate action, a restore), timed over its own calls while
    it drives the AEC env through ``decisions`` turns (1440: a whole day); with the engine's
    share of that time and the engine alone (the same calls recorded in a second run and
    replayed in bare pybullet), as for the env rows."""
    run = _planner_loop(config, decisions, seed)
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = _EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = _planner_loop(config, decisions, seed, recorder)
    finally:
        physics_module.p = real
    alone = _replay_engine_spans(recorder, recorded["spans"])
    n, spent, engine = run["decisions"], run["seconds"], run["engine_s"]
    return {"config": config, "decisions": n, "simulated": run["simulated"], "seconds": spent,
            "decisions_per_s": n / max(spent, 1e-12),
            "ms_per_simulated_decision": 1e3 * spent / max(run["simulated"], 1),
            "engine_share": engine / max(spent, 1e-12),
            "overhead_ratio": (spent - engine) / max(engine, 1e-12),
            "overhead_ratio_engine_alone": (spent - alone) / max(alone, 1e-12)}


#: Layouts for the cost against fleet size: (label, config, overrides).
FLEET_SIZES = (("4 eVTOLs (paper)", "paper", {}), ("8 eVTOLs (wide)", "wide", {}),
               ("16 eVTOLs (large)", "large", {}),
               ("32 eVTOLs (fleet40 layout)", "fleet40", {"fleet_size": 32}))


def bench_fleet_sizes(days: int, repeats: int, seed: int = 2200) -> list[dict[str, Any]]:
    """µs per AEC step under the dispatcher's recorded traffic for 4, 8, 16 and 32 eVTOLs."""
    from marl_vertiport.config import load_config

    rows = []
    for label, name, overrides in FLEET_SIZES:
        cfg = load_config(name, **overrides)
        traffic = record_traffic("heuristic", cfg, days, seed)
        steps = sum(len(day) for day in traffic)
        runs = [_env_loop("aec", cfg, steps, seed, traffic=traffic) for _ in range(repeats)]
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


def _api_floor_loop(api: str, steps: int, actions: int = 14, agents: int = 4) -> float:
    """Seconds per step of the benchmark loop's API calls and random choice of a legal action
    (without its per-step timers) over an env that does nothing: a PettingZoo AEC env behind
    the same order-enforcing wrapper as ours, or a plain Gymnasium env, each returning a fixed
    observation with an all-legal mask. No env built on these APIs and driven by this loop can
    cost less per step."""
    import gymnasium
    from pettingzoo import AECEnv

    from marl_vertiport.vertiport_v0 import OrderEnforcing, reset_agent_dicts

    obs = {"action_mask": np.ones(actions, dtype=np.int8)}
    rng = np.random.default_rng(0)

    class NoopAEC(AECEnv):
        metadata = {"name": "noop_v0", "is_parallelizable": False}

        def __init__(self) -> None:
            super().__init__()
            self.possible_agents = [f"a{i}" for i in range(agents)]

        def reset(self, seed=None, options=None) -> None:
            reset_agent_dicts(self)
            self.turn = 0
            self.agent_selection = self.agents[0]

        def observe(self, agent):
            return obs

        def step(self, action) -> None:
            self.turn += 1
            self.agent_selection = self.agents[self.turn % agents]

    class NoopGym(gymnasium.Env):
        def reset(self, seed=None, options=None):
            return obs, {}

        def step(self, action):
            return obs, 0.0, False, False, {}

    pc = time.perf_counter
    if api == "aec":
        env = OrderEnforcing(NoopAEC())
        env.reset(seed=0)
        start, n = pc(), 0
        for _ in env.agent_iter(steps):
            o, _, term, trunc, _ = env.last()
            legal = np.flatnonzero(o["action_mask"])
            env.step(int(legal[rng.integers(legal.size)]))
            n += 1
    else:
        env = NoopGym()
        o, _ = env.reset(seed=0)
        start, n = pc(), steps
        for _ in range(steps):
            legal = np.flatnonzero(o["action_mask"])
            o, _, _, truncated, _ = env.step(int(legal[rng.integers(legal.size)]))
    return (pc() - start) / n


def bench_api_floor(steps: int, repeats: int) -> list[dict[str, Any]]:
    """Median µs per step of :func:`_api_floor_loop` for both APIs."""
    return [{"api": api, "us_per_step": 1e6 * statistics.median(
        _api_floor_loop(api, steps) for _ in range(repeats))} for api in ("aec", "single_agent")]


def bench_profile(days: int, top: int = 14, seed: int = 2300) -> dict[str, Any]:
    """cProfile of the AEC env on the paper's layout replaying ``days`` days of the dispatcher's
    recorded traffic (the busy path, not random play): the functions called at least once every
    100 steps (not the env's construction) with the largest own time, as shares of the profiled
    run's total (cProfile's own cost inflates small calls)."""
    import cProfile
    import pstats

    traffic = record_traffic("heuristic", "paper", days, seed)
    steps = sum(len(day) for day in traffic)
    _env_loop("aec", "paper", 50, seed=seed, traffic=traffic)  # first-call caches outside
    profiler = cProfile.Profile()
    profiler.enable()
    _env_loop("aec", "paper", steps, seed=seed, traffic=traffic)
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    total = sum(row[2] for row in stats.values())
    per_step = [kv for kv in stats.items() if kv[1][1] >= steps / 100]
    rows = sorted(per_step, key=lambda kv: -kv[1][2])[:top]
    root = str(Path(__file__).resolve().parents[2])
    entries = []
    for (filename, line, name), (_, calls, own, cumulative, _) in rows:
        if "site-packages" in filename:
            where = filename.split("site-packages" + os.sep, 1)[1]
        else:
            where = filename.replace(root + os.sep, "") if filename.startswith(root) else Path(filename).name
        label = f"{where}:{line}({name})" if line else name
        entries.append({"function": label, "calls_per_step": calls / steps,
                        "own_share": own / total, "cumulative_share": cumulative / total})
    return {"steps": steps, "workload": "heuristic", "top": entries}


def bench_vector(steps: int, copies: int) -> list[dict[str, Any]]:
    import torch

    from agents.training.vec_env import SingleAgentVecEnv

    rows = []
    for n_copies, procs in ((copies, 1), (2, 1), (2, 2)):
        env = SingleAgentVecEnv("paper", num_envs=n_copies, multiprocessing=procs > 1)
        rng = np.random.default_rng(0)
        obs = env.get_observations()
        start = time.perf_counter()
        for _ in range(steps):
            mask = obs["action_mask"].numpy()
            actions = [rng.choice(np.flatnonzero(m)) for m in mask]
            obs, *_ = env.step(torch.tensor(actions, dtype=torch.float32).unsqueeze(-1))
        elapsed = time.perf_counter() - start
        env.close()
        rows.append({"copies": n_copies, "processes": procs,
                     "env_steps_per_s": steps * n_copies / elapsed})
        print(f"  vector {n_copies} copies, {procs} process(es): {rows[-1]['env_steps_per_s']:8.0f} steps/s",
              file=sys.stderr)
    return rows


def bench_inference(repeats: int = 200) -> list[dict[str, Any]]:
    import torch

    from agents.gcn.models import GraphActor
    from agents.gcn.features import POLICY_GROUPS, feature_names
    from agents.training.vec_env import MultiAgentVecEnv

    torch.set_num_threads(1)
    env = MultiAgentVecEnv("paper", num_envs=16)  # 64 rows
    obs = env.get_observations()
    env.close()
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    actor.eval()
    rows = []
    for batch in (1, 64):
        sub = obs[:batch]
        with torch.no_grad():
            for _ in range(10):
                actor(sub)
            times = []
            for _ in range(repeats):
                t = time.perf_counter()
                actor(sub)
                times.append(time.perf_counter() - t)
        rows.append({"batch": batch, "latency_ms_median": 1e3 * statistics.median(times),
                     "latency_ms_p90": 1e3 * float(np.percentile(times, 90))})
        print(f"  actor batch {batch:3d}: {rows[-1]['latency_ms_median']:.2f} ms", file=sys.stderr)
    return rows


def _child_peak_rss_mb(code: str) -> tuple[float, str]:
    """Run ``code`` in a fresh interpreter; its peak resident memory (MB) and its stdout.

    The peak is the child's own ``VmHWM`` (Linux): ``ru_maxrss`` would also count the parent's
    high-water mark, which Linux carries across fork and exec."""
    probe = ("\nimport resource\ntry:\n"
             "    peak = [int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
             "except (OSError, IndexError):\n"
             "    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
             "print('PEAK', peak)")
    out = subprocess.run([sys.executable, "-c", code + probe], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2])
    peak_kb = float(out.stdout.strip().split("PEAK")[-1])
    return peak_kb / 1024.0, out.stdout


def bench_training(iterations: int) -> dict[str, Any]:
    """``make train``'s config for a few PPO iterations (no warm start), in a fresh process."""
    code = (
        "import time, torch, json\n"
        "from agents.training.config import load_train_config\n"
        "from agents.training.runner import make_vec_env, runner_config\n"
        "from rsl_rl.runners import OnPolicyRunner\n"
        "cfg = load_train_config('default'); torch.set_num_threads(cfg.torch_threads)\n"
        "env = make_vec_env(cfg)\n"
        "runner = OnPolicyRunner(env, runner_config(cfg), log_dir=None, device='cpu')\n"
        "runner.learn(1)\n"
        f"t = time.perf_counter(); runner.learn({iterations}); dt = time.perf_counter() - t\n"
        f"print('RESULT', json.dumps({{'iterations': {iterations}, 'seconds': dt, "
        "'env_steps_per_s': "
        f"{iterations} * cfg.num_envs * cfg.num_steps_per_env / dt, 'mode': cfg.mode}}))\n"
    )
    peak, stdout = _child_peak_rss_mb(code)
    result = json.loads(stdout.split("RESULT", 1)[1].split("\n", 1)[0])
    result["peak_memory_mb"] = peak
    print(f"  training: {result['env_steps_per_s']:.0f} env steps/s, peak {peak:.0f} MB", file=sys.stderr)
    return result


def bench_env_memory() -> float:
    code = ("from marl_vertiport import vertiport_v0\nimport numpy as np\n"
            "env = vertiport_v0.env(); env.reset(seed=0)\n"
            "for a in env.agent_iter(1440):\n"
            "    o, *_ = env.last(); env.step(int(np.flatnonzero(o['action_mask'])[0]))\n")
    peak, _ = _child_peak_rss_mb(code)
    print(f"  env peak memory: {peak:.0f} MB", file=sys.stderr)
    return peak


