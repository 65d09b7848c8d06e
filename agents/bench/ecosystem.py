"""The env's speed through each library of docs/ecosystem.md's compatibility table
(``python -m agents.bench.ecosystem``, ``make bench-ecosystem``): env steps per second under
random legal play through each API and wrapper, and training steps per second of each
library's reference learner. A library whose extra is missing is reported as such.

One process, one torch thread, the paper's vertiport, the median of ``--repeats`` timed runs.
Writes ``<out>/ecosystem.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.files import write_atomic
from agents.common.provenance import provenance

CONFIG = "paper"


def _legal(mask: np.ndarray, rng: np.random.Generator) -> int:
    legal = np.flatnonzero(mask)
    return int(legal[rng.integers(legal.size)])


def aec_steps(steps: int, seed: int) -> int:
    from marl_vertiport import vertiport_v1

    env, rng, n = vertiport_v1.env(config=CONFIG), np.random.default_rng(seed), 0
    env.reset(seed=seed)
    while n < steps:
        for _ in env.agent_iter():
            obs, _, term, trunc, _ = env.last()
            if term or trunc:
                env.step(None)
                continue
            env.step(_legal(obs["action_mask"], rng))
            n += 1
            if n >= steps:
                break
        else:
            env.reset(seed=seed + n)
    return n


def parallel_steps(steps: int, seed: int, flat: bool = False) -> int:
    from marl_vertiport import vertiport_v1
    from marl_vertiport.flat import FlatParallel

    env = vertiport_v1.parallel_env(config=CONFIG)
    if flat:
        env = FlatParallel(env)
    rng = np.random.default_rng(seed)
    obs, infos = env.reset(seed=seed)
    for n in range(steps):
        if not env.agents:
            obs, infos = env.reset(seed=seed + n)
        masks = {a: (infos[a]["action_mask"] if flat else obs[a]["action_mask"]) for a in env.agents}
        obs, _, _, _, infos = env.step({a: _legal(m, rng) for a, m in masks.items()})
    return steps


def gym_steps(steps: int, seed: int, flat: bool = False) -> int:
    import gymnasium

    import marl_vertiport  # noqa: F401

    env = gymnasium.make("marl_vertiport/VertiportFlat-v1" if flat else
                         "marl_vertiport/Vertiport-v1", config=CONFIG)
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    for n in range(steps):
        mask = info["action_mask"] if flat else obs["action_mask"]
        obs, _, _, truncated, info = env.step(_legal(mask, rng))
        if truncated:
            obs, info = env.reset(seed=seed + n)
    return steps


def supersuit_steps(steps: int, seed: int) -> int:
    """SuperSuit's vector env over the Parallel env (one env step = one ATC turn of 4 agents)."""
    import supersuit as ss

    from marl_vertiport import vertiport_v1

    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(
        vertiport_v1.parallel_env(config=CONFIG)), 1, num_cpus=0, base_class="gymnasium")
    rng = np.random.default_rng(seed)
    obs, _ = venv.reset(seed=seed)
    for _ in range(steps):
        obs, *_ = venv.step(np.array([_legal(m, rng) for m in obs["action_mask"]]))
    return steps


def torchrl_steps(steps: int, seed: int, api: str) -> int:
    from agents.interop import torchrl_env

    make = {"aec": torchrl_env.make_env, "parallel": torchrl_env.make_parallel_env}[api]
    env = make(CONFIG, seed=seed)
    env.rollout(steps, break_when_any_done=False)
    return steps


def sb3_training(steps: int, seed: int) -> int:
    from agents.interop import sb3

    sb3.train(CONFIG, steps=steps, seed=seed, n_steps=1024, batch_size=256, n_epochs=4)
    return steps


def torchrl_training(steps: int, seed: int) -> int:
    import torch

    from agents.interop import torchrl_env

    torch.manual_seed(seed)
    env = torchrl_env.make_parallel_env(CONFIG, seed=seed, flat=True)
    actor, critic = torchrl_env.make_actor(env), torchrl_env.make_critic(env)
    batch = 512
    for _ in torchrl_env.ppo(env, actor, critic, iterations=max(1, steps // batch),
                             frames_per_batch=batch, epochs=4, minibatch_size=128):
        pass
    return max(1, steps // batch) * batch


#: The RLlib algorithm of the timed runs, built once (building it is not training).
_RLLIB: dict[str, Any] = {}
RLLIB_BATCH = 512


def rllib_training(steps: int, seed: int) -> int:
    """RLlib's PPO (``agents.interop.rllib_env.ppo_config``: env runner and learner in this
    process) for ``steps // 512`` iterations of 512 AEC steps; the algorithm is built once."""
    import ray

    from agents.interop import rllib_env

    if "algo" not in _RLLIB:
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
                 ignore_reinit_error=True)
        config = rllib_env.ppo_config({"config": CONFIG}, seed=seed, batch_size=RLLIB_BATCH,
                                      minibatch_size=128, epochs=4)
        _RLLIB["algo"] = config.build_algo()
    iterations = max(1, steps // RLLIB_BATCH)
    for _ in range(iterations):
        _RLLIB["algo"].train()
    return iterations * RLLIB_BATCH


def _stop_rllib() -> None:
    if "algo" in _RLLIB:
        import ray

        _RLLIB.pop("algo").stop()
        ray.shutdown()


#: name -> (what it measures, extra it needs or None, function(steps, seed) -> steps done)
MEASURES: dict[str, tuple[str, str | None, Callable[[int, int], int]]] = {
    "pettingzoo_aec": ("vertiport_v1.env(), random legal play", None, aec_steps),
    "pettingzoo_parallel": ("vertiport_v1.parallel_env(), random legal play", None, parallel_steps),
    "pettingzoo_parallel_flat": ("FlatParallel(parallel_env()), random legal play", None,
                                 lambda s, k: parallel_steps(s, k, flat=True)),
    "gymnasium": ("gymnasium.make('marl_vertiport/Vertiport-v1')", None, gym_steps),
    "gymnasium_flat": ("gymnasium.make('marl_vertiport/VertiportFlat-v1')", None,
                       lambda s, k: gym_steps(s, k, flat=True)),
    "supersuit_vec": ("concat_vec_envs_v1(pettingzoo_env_to_vec_env_v1(parallel_env()))", None,
                      supersuit_steps),
    "torchrl_aec": ("PettingZooWrapper(env(), use_mask=True).rollout", "torchrl",
                    lambda s, k: torchrl_steps(s, k, "aec")),
    "torchrl_parallel": ("PettingZooWrapper(parallel_env()) as BenchMARL builds it, rollout",
                         "torchrl", lambda s, k: torchrl_steps(s, k, "parallel")),
    "sb3_maskable_ppo": ("MaskablePPO('MlpPolicy') training on VertiportFlat-v1 (the recipe's "
                         "and the docs snippet's settings)", "sb3", sb3_training),
    "torchrl_ppo_parallel": ("agents.interop.torchrl_env.ppo on the flat Parallel env", "torchrl",
                             torchrl_training),
    "rllib_ppo": ("RLlib PPO (agents.interop.rllib_env.ppo_config) training on the AEC env",
                  "rllib", rllib_training),
}

#: The module each extra provides (a missing one skips its rows).
EXTRA_MODULES = {"torchrl": "torchrl", "sb3": "sb3_contrib", "rllib": "ray.rllib"}


def measure(name: str, steps: int, repeats: int, seed: int = 2400) -> dict[str, Any]:
    what, extra, fn = MEASURES[name]
    row: dict[str, Any] = {"name": name, "what": what, "extra": extra}
    if extra is not None:
        try:
            __import__(EXTRA_MODULES[extra])
        except ImportError:
            return dict(row, missing=f"pip install -e '.[{extra}]'")
    fn(min(steps, 200), seed)  # warm-up: imports, first allocations
    rates = []
    for r in range(repeats):
        start = time.perf_counter()
        done = fn(steps, seed + r)
        rates.append(done / (time.perf_counter() - start))
    return dict(row, steps=steps, repeats=repeats, steps_per_s=statistics.median(rates),
                min_steps_per_s=min(rates), max_steps_per_s=max(rates))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.bench.ecosystem", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=3000, help="env steps per timed run")
    parser.add_argument("--train-steps", type=int, default=4096,
                        help="env steps per timed training run")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per row (median)")
    parser.add_argument("--only", nargs="+", choices=sorted(MEASURES), default=None)
    parser.add_argument("--out", default="runs/bench", help="folder for ecosystem.json")
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    warnings.filterwarnings("ignore")  # libraries' version notices; they are not results
    rows = []
    for name in args.only or list(MEASURES):
        steps = args.train_steps if "ppo" in name else args.steps
        print(f"  {name} ...", file=sys.stderr, flush=True)
        try:
            rows.append(measure(name, steps, args.repeats))
        finally:
            if name == "rllib_ppo":
                _stop_rllib()
    result = {"command": " ".join(["python -m agents.bench.ecosystem", *(argv or sys.argv[1:])]),
              "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
              "python": platform.python_version(), "provenance": provenance(), "rows": rows}
    write_atomic(Path(args.out) / "ecosystem.json", json.dumps(result, indent=2))
    print(f"{'row':26} {'steps/s':>9}  (min-max)  what")
    for row in rows:
        if "missing" in row:
            print(f"{row['name']:26} {'-':>9}  not installed: {row['missing']}")
        else:
            print(f"{row['name']:26} {row['steps_per_s']:9.0f}  ({row['min_steps_per_s']:.0f}-"
                  f"{row['max_steps_per_s']:.0f})  {row['what']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
