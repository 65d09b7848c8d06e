"""The learner's side: vectorised env throughput, actor inference latency, training
throughput of ``make train``'s config and peak memory (the last two in processes of their own,
:mod:`agents.bench.child`)."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np


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
        rows.append({"batch": batch, "path": "torch",
                     "latency_ms_median": 1e3 * statistics.median(times),
                     "latency_ms_p90": 1e3 * float(np.percentile(times, 90))})
        print(f"  actor batch {batch:3d}: {rows[-1]['latency_ms_median']:.2f} ms", file=sys.stderr)
    rows.append(_numpy_latency(actor, repeats))
    print(f"  actor batch   1, NumPy: {rows[-1]['latency_ms_median']:.3f} ms", file=sys.stderr)
    return rows


def _numpy_latency(actor, repeats: int) -> dict[str, Any]:
    """The greedy controller's path (agents/gcn/fast.py): one AEC observation of a dispatcher's
    day on `paper`, scored by the actor's NumPy forward pass."""
    from agents.controllers.dispatcher import DispatcherController
    from agents.gcn.fast import FastGraphActor
    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env(config="paper")
    env.reset(seed=0)
    dispatcher = DispatcherController()
    dispatcher.bind(env.unwrapped.sim)
    observations = []
    for _ in range(200):  # observations of vehicles in every status
        obs = env.observe(env.agent_selection)
        observations.append(obs)
        env.step(dispatcher.act(obs))
    env.close()
    fast = FastGraphActor(actor)
    for obs in observations[:10]:
        fast.act(obs)
    times = []
    for k in range(repeats):
        obs = observations[k % len(observations)]
        t = time.perf_counter()
        fast.act(obs)
        times.append(time.perf_counter() - t)
    return {"batch": 1, "path": "numpy", "latency_ms_median": 1e3 * statistics.median(times),
            "latency_ms_p90": 1e3 * float(np.percentile(times, 90))}


def child_run(*args: str) -> tuple[dict[str, Any], float]:
    """``python -m agents.bench.child ARGS`` in a fresh interpreter: its result and its peak
    resident memory (MB)."""
    out = subprocess.run([sys.executable, "-m", "agents.bench.child", *args], capture_output=True,
                         text=True, check=True, cwd=Path(__file__).resolve().parents[2])
    result = json.loads(out.stdout.split("RESULT", 1)[1].split("\n", 1)[0])
    return result, float(out.stdout.strip().split("PEAK")[-1]) / 1024.0


def bench_training(iterations: int) -> dict[str, Any]:
    """``make train``'s config for a few PPO iterations (no warm start), in a fresh process."""
    result, peak = child_run("training", str(iterations))
    result["peak_memory_mb"] = peak
    print(f"  training: {result['env_steps_per_s']:.0f} env steps/s, peak {peak:.0f} MB", file=sys.stderr)
    return result


def bench_env_memory() -> float:
    """Peak memory (MB) of a process that runs one day of the AEC env."""
    _, peak = child_run("env-memory")
    print(f"  env peak memory: {peak:.0f} MB", file=sys.stderr)
    return peak
