"""A controller's recorded traffic replayed through the AEC env, timed: the bare loop, run as a
script of its own (``python agents/bench/replay.py TRAFFIC.json --config paper``) so that it can
time the env of another checkout (``PYTHONPATH=<checkout>``; :mod:`agents.bench.compare`).

It imports nothing of ``agents`` and of the env only ``marl_vertiport.vertiport_v1.env``, and
prints one line of JSON: ``{"steps": ..., "seconds": ..., "steps_per_s": ..., "env": <the
marl_vertiport file that ran>}``. ``TRAFFIC.json`` holds ``{"config": ..., "seed": ...,
"days": [[action, ...], ...]}`` (day ``d`` starts from ``seed + d``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def replay(traffic: dict) -> dict:
    """Every day of ``traffic`` through a new AEC env: reset, then each recorded action in turn
    (the episode's end stepped with ``None``); the time of the loop alone."""
    import marl_vertiport
    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env(config=traffic["config"])
    steps = 0
    pc = time.perf_counter
    elapsed = 0.0
    for d, actions in enumerate(traffic["days"]):
        env.reset(seed=traffic["seed"] + d)
        k = 0
        start = pc()
        for _agent in env.agent_iter():
            _, _, term, trunc, _ = env.last()
            if term or trunc:
                env.step(None)
                continue
            env.step(actions[k])
            k += 1
        elapsed += pc() - start
        if k != len(actions):
            raise RuntimeError(f"day {d}: {k} actions taken, {len(actions)} recorded")
        steps += k
    env.close()
    return {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed,
            "env": marl_vertiport.__file__}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("traffic", help="the recorded traffic (JSON)")
    args = parser.parse_args(argv)
    with open(args.traffic) as fh:
        traffic = json.load(fh)
    print(json.dumps(replay(traffic)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
