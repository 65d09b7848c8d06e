"""What a step costs beyond the engine: the floor of the APIs themselves (the benchmark's loop
over envs that do nothing) and a profile of the env under the dispatcher's traffic."""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.bench.env import env_loop, record_traffic


def api_floor_loop(api: str, steps: int, actions: int = 14, agents: int = 4) -> float:
    """Seconds per step of the benchmark loop's API calls and random choice of a legal action
    (without its per-step timers) over an env that does nothing: a PettingZoo AEC env behind
    the same order-enforcing wrapper as ours, or a plain Gymnasium env, each returning a fixed
    observation with an all-legal mask. No env built on these APIs and driven by this loop can
    cost less per step."""
    import gymnasium
    from pettingzoo import AECEnv

    from marl_vertiport.vertiport_v1 import OrderEnforcing, reset_agent_dicts

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
    """Median µs per step of :func:`api_floor_loop` for both APIs."""
    return [{"api": api, "us_per_step": 1e6 * statistics.median(
        api_floor_loop(api, steps) for _ in range(repeats))} for api in ("aec", "single_agent")]

def bench_profile(days: int, top: int = 14, seed: int = 2300) -> dict[str, Any]:
    """cProfile of the AEC env on the paper's layout replaying ``days`` days of the dispatcher's
    recorded traffic (the busy path, not random play): the functions called at least once every
    100 steps (not the env's construction) with the largest own time, as shares of the profiled
    run's total (cProfile's own cost inflates small calls)."""
    import cProfile
    import pstats

    traffic = record_traffic("dispatcher", "paper", days, seed)
    steps = sum(len(day) for day in traffic)
    env_loop("aec", "paper", 50, seed=seed, traffic=traffic)  # first-call caches outside
    profiler = cProfile.Profile()
    profiler.enable()
    env_loop("aec", "paper", steps, seed=seed, traffic=traffic)
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
    return {"steps": steps, "workload": "dispatcher", "top": entries}
