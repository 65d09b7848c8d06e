"""``python -m agents.bench`` (``make bench``): the speed of the simulator and of training,
measured on the machine it runs on. Writes ``bench.json`` and a Markdown report.

Measured:

- env steps per second in one process, AEC and single-agent, random legal actions, nominal and
  uncertain configs, the paper's 4 eVTOLs and the 16-eVTOL ``large`` layout: median and spread
  over repeats;
- in the same runs, the time spent inside the physics engine's calls (stepping, body updates,
  position reads, contacts) and so the ratio of our own overhead to the engine's cost, over all
  steps and over the steps in which bodies move;
- the engine alone for the same motion: each run's pybullet calls recorded in a second run of
  the same seed and replayed, timed, in bare pybullet;
- a cProfile summary of the AEC env on the paper's layout;
- vectorised throughput of K env copies with supersuit, in one process and over 2 processes;
- actor inference latency at batch 1 and 64, training throughput (env samples per second) of
  ``make train``'s config, and peak memory of an env and of a training run (separate processes).

No number is asserted anywhere: the benchmark reports what it measures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.files import write_atomic

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
        self.clients: set[int] = set()

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._module, name)
        if not callable(attr) or isinstance(attr, type):  # constants and the error class
            return attr
        calls, clients = self.calls, self.clients
        connect, disconnect = self._module.connect, self._module.disconnect

        def call(*args: Any, **kwargs: Any) -> Any:
            result = attr(*args, **kwargs)
            if attr is connect:
                clients.add(result)
                calls.append((attr, args, kwargs))
            elif attr is not disconnect and kwargs.get("physicsClientId") in clients:
                calls.append((attr, args, kwargs))
            return result

        return call


def _env_loop(api: str, config: str, steps: int, seed: int,
              recorder: _EngineCallRecorder | None = None) -> dict[str, float]:
    """``steps`` env steps with random legal actions from ``seed``, timed, one process.

    With ``recorder`` the engine calls are recorded (and the timings are not representative);
    ``first_timed_call`` is then the index of the first call made inside the timed loop."""
    rng = np.random.default_rng(seed)
    pc = time.perf_counter
    moving_s = moving_engine_s = 0.0
    if api == "aec":
        from marl_vertiport import vertiport_v0

        env = vertiport_v0.env(config=config)
        env.reset(seed=seed)
        physics = env.unwrapped.sim.physics
        physics.engine_seconds, physics.engine_steps = 0.0, 0
        first_call = len(recorder.calls) if recorder else 0
        n = 0
        start = pc()
        while n < steps:
            for agent in env.agent_iter():
                t, engine, engine_steps = pc(), physics.engine_seconds, physics.engine_steps
                obs, _, term, trunc, _ = env.last()
                if term or trunc:
                    env.step(None)
                    continue
                legal = np.flatnonzero(obs["action_mask"])
                env.step(int(legal[rng.integers(legal.size)]))
                if physics.engine_steps != engine_steps:
                    moving_s += pc() - t
                    moving_engine_s += physics.engine_seconds - engine
                n += 1
                if n >= steps:
                    break
            else:
                env.reset(seed=seed + n)
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


def _replay_engine(calls: list[tuple[Any, tuple, dict]], first_timed: int, last_timed: int) -> float:
    """Replay recorded pybullet calls on a fresh client; seconds taken by the calls of the timed
    loop (``calls[first_timed:last_timed]``), with nothing but a loop around them."""
    from marl_vertiport.sim import physics as physics_module

    p = physics_module.p
    client = p.connect(p.DIRECT)

    def on_client(kwargs: dict) -> dict:
        return dict(kwargs, physicsClientId=client) if "physicsClientId" in kwargs else kwargs

    for fn, args, kwargs in calls[:first_timed]:  # the world as it was when the loop started
        if fn is not p.connect:
            fn(*args, **on_client(kwargs))
    timed = [(fn, args, on_client(kwargs)) for fn, args, kwargs in calls[first_timed:last_timed]]
    start = time.perf_counter()
    for fn, args, kwargs in timed:
        fn(*args, **kwargs)
    elapsed = time.perf_counter() - start
    p.disconnect(physicsClientId=client)
    return elapsed


def _env_run(api: str, config: str, steps: int, seed: int) -> dict[str, float]:
    """One timed run of ``steps`` env steps with random legal actions, and the engine alone
    replaying the same motion: a second, untimed run of the same seed records its pybullet
    calls, which are then replayed in bare pybullet and timed."""
    run = _env_loop(api, config, steps, seed)
    from marl_vertiport.sim import physics as physics_module

    real = physics_module.p
    recorder = _EngineCallRecorder(real)
    physics_module.p = recorder
    try:
        recorded = _env_loop(api, config, steps, seed, recorder)
    finally:
        physics_module.p = real
    alone = _replay_engine(recorder.calls, recorded["first_timed_call"], recorded["last_timed_call"])
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
        rate = [run["steps_per_s"] for run in case_runs]

        def median(key: str, scale: float = 1.0) -> float:
            return scale * statistics.median(run[key] for run in case_runs)

        rows.append({
            "api": api, "config": config, "steps": steps, "repeats": repeats,
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
        })
        print(f"  env {api:12s} {config:16s} {rows[-1]['steps_per_s_median']:8.0f} steps/s "
              f"(overhead/engine {rows[-1]['overhead_ratio']:.2f}, in steps with motion "
              f"{rows[-1]['moving_overhead_ratio']:.2f})", file=sys.stderr)
    return rows


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


def bench_profile(steps: int, top: int = 12) -> dict[str, Any]:
    """cProfile of one AEC run on the paper's layout: the functions called at least once every
    100 steps (not the env's construction) with the largest own time, as shares of the profiled
    run's total (cProfile's own cost inflates small calls)."""
    import cProfile
    import pstats

    _env_loop("aec", "paper", 50, seed=7)  # imports and first-call caches outside the profile
    profiler = cProfile.Profile()
    profiler.enable()
    _env_loop("aec", "paper", steps, seed=7)
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    total = sum(row[2] for row in stats.values())
    per_step = [kv for kv in stats.items() if kv[1][1] >= steps / 100]
    rows = sorted(per_step, key=lambda kv: -kv[1][2])[:top]
    root = str(Path(__file__).resolve().parents[1])
    entries = []
    for (filename, line, name), (_, calls, own, cumulative, _) in rows:
        if "site-packages" in filename:
            where = filename.split("site-packages" + os.sep, 1)[1]
        else:
            where = filename.replace(root + os.sep, "") if filename.startswith(root) else Path(filename).name
        label = f"{where}:{line}({name})" if line else name
        entries.append({"function": label, "calls_per_step": calls / steps,
                        "own_share": own / total, "cumulative_share": cumulative / total})
    return {"steps": steps, "top": entries}


def bench_vector(steps: int, copies: int) -> list[dict[str, Any]]:
    import torch

    from agents.gcn.vec_env import SingleAgentVecEnv

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
    from agents.gcn.training import feature_names
    from agents.gcn.vec_env import POLICY_GROUPS, MultiAgentVecEnv

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
                         check=True, cwd=Path(__file__).resolve().parents[1])
    peak_kb = float(out.stdout.strip().split("PEAK")[-1])
    return peak_kb / 1024.0, out.stdout


def bench_training(iterations: int) -> dict[str, Any]:
    """``make train``'s config for a few PPO iterations (no warm start), in a fresh process."""
    code = (
        "import time, torch, json\n"
        "from agents.gcn.training import load_train_config, make_vec_env, runner_config\n"
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


def _floor_lines(results: dict[str, Any], env_rows: list[dict[str, Any]]) -> list[str]:
    """The report's paragraph on the API floor (empty for results without one)."""
    floor = {r["api"]: r["us_per_step"] for r in results.get("api_floor", [])}
    engine = {r["api"]: r["engine_us_per_step"] for r in env_rows if r["config"] == "paper"}
    parts = []
    for api, name in (("aec", "AEC"), ("single_agent", "single-agent")):
        if api not in floor or api not in engine:
            continue
        share = floor[api] / engine[api]
        verdict = ("so there the ratio over all steps cannot come down to 1.0 whatever the "
                   "simulator costs" if share >= 1.0 else
                   f"which leaves {engine[api] - floor[api]:.1f} µs a step for the whole "
                   "simulator and its observation at a ratio of 1.0")
        parts.append(f"{floor[api]:.1f} µs a step through the {name} API, {share:.2f} times the "
                     f"engine's {engine[api]:.1f} µs a step of `paper`, {verdict}")
    if not parts:
        return []
    moving = max(floor.get(r["api"], 0.0) / r["engine_us_per_moving_step"]
                 for r in env_rows if r["config"] == "paper")
    return [
        "- The floor under that ratio: the benchmark loop's API calls and random choice of a "
        "legal action (without its per-step timers) over an env that does nothing, which "
        "returns a fixed observation with "
        "every action legal, the AEC one behind the same order-enforcing wrapper, costs "
        + "; and ".join(parts) + f". In steps with motion the floor is at most {moving:.2f} "
        "times the engine's cost; the rest of the ratio there is the simulator's own Python, "
        "which only a compiled core would bring down to the engine's cost.",
    ]


def report(results: dict[str, Any]) -> str:
    env_rows = results["env"]
    ref = next((r for r in env_rows if (r["api"], r["config"]) == ("single_agent", "paper")), env_rows[0])
    lines = [
        "# Performance",
        "",
        f"Measured by `{results['command']}` on {results['machine']} "
        f"(Python {results['python']}); regenerate with `make bench`.",
        "",
        "## Environment steps per second (one process, random legal actions)",
        "",
        "| API | config | steps/s (median) | min - max | µs per step | steps with motion | "
        "engine µs per step | engine µs per step with motion | engine alone µs per step | "
        "overhead / engine | overhead / engine, steps with motion | overhead / engine alone | "
        "x the paper's 5 steps/s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in env_rows:
        lines.append(f"| {r['api']} | {r['config']} | {r['steps_per_s_median']:,.0f} | "
                     f"{r['steps_per_s_min']:,.0f} - {r['steps_per_s_max']:,.0f} | "
                     f"{r['total_us_per_step']:.0f} | {100 * r['moving_fraction']:.0f} % | "
                     f"{r['engine_us_per_step']:.1f} | {r['engine_us_per_moving_step']:.0f} | "
                     f"{r['engine_alone_us_per_step']:.1f} | {r['overhead_ratio']:.2f} | "
                     f"{r['moving_overhead_ratio']:.2f} | {r['overhead_ratio_engine_alone']:.2f} | "
                     f"{r['times_paper']:,.0f} |")
    lines += [
        "",
        f"{env_rows[0]['repeats']} runs of {env_rows[0]['steps']:,} steps each, in interleaved "
        "rounds (each round runs every row once); every ratio is the median over the runs of "
        "the ratio within one run. On this kind of virtual machine the same run varies by up to "
        "a third from one minute to the next: read the min - max column.",
        "",
        "- **engine**: wall time inside the simulator's pybullet calls during the timed run "
        "(velocity commands, gust forces, stepping at >= 48 Hz of flight time, position reads, "
        "contact queries, switching bodies between static, dynamic and absent). The engine is "
        "stepped only in steps in which a body moves (**steps with motion**).",
        "- **overhead**: the rest of the run's wall time: the simulator's bookkeeping, "
        "observations, masks, the API layers and the benchmark's own random choice of a legal "
        "action (about 3 µs a step).",
        "- **engine alone**: after each timed run, a second run with the same seed records every "
        "pybullet call with its arguments; the calls of the timed loop are replayed on a fresh "
        "pybullet client with nothing around them but a Python loop, and timed. "
        "**overhead / engine alone** is (run time - replay time) / replay time.",
        "- **overhead / engine, steps with motion**: the same ratio counting only the steps in "
        "which the engine was stepped (each step timed on its own).",
        "",
    ]
    prof = results.get("profile")
    if prof:
        lines += [
            f"### Where a step's time goes (cProfile, AEC API, `paper`, {prof['steps']:,} steps)",
            "",
            "| function | calls per step | own time | with callees |",
            "|---|---:|---:|---:|",
        ]
        for e in prof["top"]:
            lines.append(f"| `{e['function']}` | {e['calls_per_step']:.2f} | "
                         f"{100 * e['own_share']:.1f} % | {100 * e['cumulative_share']:.1f} % |")
        lines += ["", "Functions called at least once every 100 steps; shares of the profiled "
                  "run's total. The profiler's own cost per call inflates functions that make "
                  "many small calls.", ""]
    lines += [
        "## Vectorised copies (supersuit's `gym_vec_env_v0`, single-agent env, random legal actions)",
        "",
        "| copies | processes | env steps/s |",
        "|---:|---:|---:|",
    ]
    for r in results["vector"]:
        lines.append(f"| {r['copies']} | {r['processes']} | {r['env_steps_per_s']:,.0f} |")
    lines += ["", "## Policy and training", "", "| measure | value |", "|---|---:|"]
    for r in results["inference"]:
        lines.append(f"| actor latency, batch {r['batch']} (median / p90) | "
                     f"{r['latency_ms_median']:.2f} / {r['latency_ms_p90']:.2f} ms |")
    t = results["training"]
    lines += [
        f"| training throughput (`make train` config, {t['mode']}, {t['iterations']} PPO iterations) | "
        f"{t['env_steps_per_s']:,.0f} env steps/s |",
        f"| peak memory, training process | {t['peak_memory_mb']:.0f} MB |",
        f"| peak memory, one env running a day | {results['env_peak_memory_mb']:.0f} MB |",
        "",
        "## Reading these numbers",
        "",
        f"- What bounds the overhead ratio: under random legal actions the fleet empties its "
        f"batteries within the first hours of the day (docs/results.md) and most vehicles are then "
        f"out of service, so in {100 - 100 * ref['moving_fraction']:.0f} % of the steps "
        f"({ref['api']}, {ref['config']}) no body moves and the engine is not asked to do anything, "
        f"while each step still checks the action, advances batteries, schedules and the conflict "
        f"probe and builds an observation. Per step on average that is "
        f"{ref['total_us_per_step'] - ref['engine_us_per_step']:.0f} µs of our own work against "
        f"{ref['engine_us_per_step']:.1f} µs of engine time; in the steps with motion the engine "
        f"costs {ref['engine_us_per_moving_step']:.0f} µs (12 substeps) and the ratio is "
        f"{ref['moving_overhead_ratio']:.2f}.",
        *_floor_lines(results, env_rows),
        "- Our own cost is spread over many small calls (see the profile): the simulator's step "
        "(scalar per-vehicle bookkeeping), the observation (eVTOL features built from Python rows, "
        "one conversion to float32, copies of the port graph, edges and mask) and, in the AEC API, "
        "the agent iterator of PettingZoo's order-enforcing wrapper (it reads the env through two "
        "`__getattr__` hops per attribute; the env's own `last()` skips them) and the reward "
        "and info dicts.",
        "- The single-agent API skips the AEC wrappers and reward dicts; the larger fleet costs "
        "less than proportionally more per step (per-vehicle work is a small part of a step).",
        "- Vector envs in one process pay per-copy Python and the stacking of observations; "
        "separate processes add inter-process copies of nested Dict observations, which on 2 cores "
        "costs more than it gains.",
        "- Training throughput is bounded by the graph models' forward and backward passes on "
        "batches of up to 128 rows and by stepping 32 env copies in the training process.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.bench", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per timed run")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per measurement")
    parser.add_argument("--configs", nargs="+", default=["paper", "paper_uncertain", "large"])
    parser.add_argument("--vector-steps", type=int, default=400)
    parser.add_argument("--copies", type=int, default=16)
    parser.add_argument("--train-iterations", type=int, default=5)
    parser.add_argument("--out", default="runs/bench", help="folder for bench.json")
    parser.add_argument("--report", default=None, help="write the Markdown report here")
    args = parser.parse_args(argv)
    results: dict[str, Any] = {
        "command": "python -m agents.bench " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores", "python": platform.python_version(),
    }
    print("benchmarking (each part in turn) ...", file=sys.stderr)
    results["env"] = bench_env(args.steps, args.repeats, args.configs)
    results["api_floor"] = bench_api_floor(args.steps, args.repeats)
    results["profile"] = bench_profile(args.steps)
    results["vector"] = bench_vector(args.vector_steps, args.copies)
    results["inference"] = bench_inference()
    results["training"] = bench_training(args.train_iterations)
    results["env_peak_memory_mb"] = bench_env_memory()
    write_atomic(Path(args.out) / "bench.json", json.dumps(results, indent=2))
    text = report(results)
    if args.report:
        write_atomic(Path(args.report), text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
