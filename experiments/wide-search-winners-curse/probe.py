"""Re-scores the wide search's choices with fresh draws: for every decision where the search
took another action than the dispatcher's (its rollout policy), the two are rolled out again,
``--fresh`` times each with draws the search never saw. Writes one CSV row per such decision:
the gain in reward (and in vehicles lost) the search estimated for its choice over the
dispatcher's, and the gain the fresh rollouts give.

    python experiments/wide-search-winners-curse/probe.py --seeds 802000:802003 \\
        --out runs/winners_curse.csv
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # so `agents` imports

import agents.controllers.guard as guard_module  # noqa: E402
from agents.controllers.episode import run_episode  # noqa: E402
from agents.controllers.registry import make_controller  # noqa: E402
from marl_vertiport import vertiport_v1  # noqa: E402

FIELDS = ["seed", "step", "candidates", "base", "chosen", "est_reward_gain", "est_lost_gain",
          "fresh_reward_gain", "fresh_lost_gain"]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--agent", default="lookahead[proposer=dispatcher,candidates=1,horizon_min=40]")
    ap.add_argument("--config", default="paper_uncertain_10")
    ap.add_argument("--seeds", default="802000:802003")
    ap.add_argument("--fresh", type=int, default=16, help="fresh rollouts per action")
    ap.add_argument("--out", type=Path, default=Path("runs/winners_curse.csv"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    start, stop = (int(x) for x in args.seeds.split(":"))
    original = guard_module.wide_choice
    rows: list[dict] = []

    def probed(guard, sim, observation, legal):
        chosen = original(guard, sim, observation, legal)
        values = guard.last_values
        base = next(iter(values))  # the rollout policy's choice comes first
        if chosen != base:
            settings = guard.settings
            guard.settings = dataclasses.replace(settings, seed=settings.seed + 10_007)
            try:
                fresh, _ = guard.evaluate(sim, [base, chosen], runs=args.fresh)
            finally:
                guard.settings = settings
            rows.append({"seed": seed, "step": sim.step_count, "candidates": len(values),
                         "base": base, "chosen": chosen,
                         "est_reward_gain": values[chosen][1] - values[base][1],
                         "est_lost_gain": values[base][0] - values[chosen][0],
                         "fresh_reward_gain": fresh[chosen][1] - fresh[base][1],
                         "fresh_lost_gain": fresh[base][0] - fresh[chosen][0]})
        return chosen

    guard_module.wide_choice = probed
    env = vertiport_v1.env(config=args.config)
    for seed in range(start, stop):
        before = len(rows)
        metrics = run_episode(env, make_controller(args.agent), seed=seed)
        print(f"day {seed}: reward {metrics['total_reward']:.0f}, lost {metrics['stranded']}, "
              f"{len(rows) - before} decisions changed", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {args.out}: {len(rows)} decisions")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
