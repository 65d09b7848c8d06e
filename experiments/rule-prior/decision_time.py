"""Decision time of the policies that act from the observation alone: at every decision with a
choice of a day of case 2 (the dispatcher driving), each controller decides the same
observation; median and 99th percentile in milliseconds, one torch thread.

    python experiments/rule-prior/decision_time.py [CHECKPOINT ...]
"""

import sys
import time

import numpy as np
import torch

from agents.controllers.episode import run_episode
from agents.controllers.registry import make_controller
from marl_vertiport import vertiport_v1

torch.set_num_threads(1)
specs = ["dispatcher", "gcn", "prior", *(f"prior[policy={p}]" for p in sys.argv[1:])]
controllers = {spec: make_controller(spec) for spec in specs}
times: dict[str, list[float]] = {spec: [] for spec in specs}
env = vertiport_v1.env(config="paper_uncertain")


def before(agent, obs, env):
    if obs["action_mask"].sum() < 2:
        return
    for spec, controller in controllers.items():
        start = time.perf_counter()
        controller.act(obs)
        times[spec].append(time.perf_counter() - start)


for controller in controllers.values():
    controller.reset(seed=1000000)
    if hasattr(controller, "bind"):
        controller.bind(env.unwrapped.sim)
run_episode(env, make_controller("dispatcher"), 1000000, before_step=before)
for spec, t in times.items():
    ms = 1000 * np.asarray(t)
    print(f"{spec}: {len(ms)} decisions, median {np.median(ms):.3f} ms, "
          f"p99 {np.percentile(ms, 99):.3f} ms")
