"""The benchmark's workloads that run in a process of their own, so that their peak memory is
theirs alone: ``python -m agents.bench.child training ITERATIONS`` (``make train``'s config for
a few PPO iterations, no warm start) and ``python -m agents.bench.child env-memory`` (a day of
the AEC env). Each prints ``RESULT <json>`` and ``PEAK <kB>``, the process's own high-water mark
(``VmHWM`` on Linux: ``ru_maxrss`` would also count the parent's, which Linux carries across
fork and exec)."""

from __future__ import annotations

import json
import resource
import sys
import time


def training(iterations: int) -> dict:
    import torch
    from rsl_rl.runners import OnPolicyRunner

    from agents.training.config import load_train_config
    from agents.training.runner import make_vec_env, runner_config

    cfg = load_train_config("default")
    torch.set_num_threads(cfg.torch_threads)
    runner = OnPolicyRunner(make_vec_env(cfg), runner_config(cfg), log_dir=None, device="cpu")
    runner.learn(1)  # first-call costs outside the timing
    start = time.perf_counter()
    runner.learn(iterations)
    seconds = time.perf_counter() - start
    return {"iterations": iterations, "seconds": seconds, "mode": cfg.mode,
            "env_steps_per_s": iterations * cfg.num_envs * cfg.num_steps_per_env / seconds}


def env_memory() -> dict:
    import numpy as np

    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env()
    env.reset(seed=0)
    for _ in env.agent_iter(1440):
        obs, *_ = env.last()
        env.step(int(np.flatnonzero(obs["action_mask"])[0]))
    return {"steps": 1440}


def peak_kb() -> float:
    try:
        with open("/proc/self/status") as fh:
            return float(next(line.split()[1] for line in fh if line.startswith("VmHWM")))
    except (OSError, StopIteration):
        return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in ("training", "env-memory"):
        print("usage: python -m agents.bench.child training ITERATIONS | env-memory", file=sys.stderr)
        return 2
    result = training(int(args[1])) if args[0] == "training" else env_memory()
    print("RESULT", json.dumps(result))
    print("PEAK", peak_kb())
    return 0


if __name__ == "__main__":
    sys.exit(main())
