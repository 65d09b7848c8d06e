"""How much energy the charging ports deliver a day, and where their time goes
(``marl-vertiport charger-study``).

For each fleet size it runs a controller for whole days and accounts for every minute of every
charging port: a vehicle *approaching* it (cleared to land on it, not down yet), *charging*
(on it, below 100 %), *parked full* (on it at 100 %, charging nothing) or *free*; with the
energy delivered, the number of charging sessions and the vehicles lost a day. It is the study
behind experiments/lost-vehicles-charger-rules-v0::

    marl-vertiport charger-study --agent dispatcher --config paper --fleet 3 4 5

Days are validation seeds (800 000 onwards) unless ``--seeds`` says otherwise; training seeds
are refused. The table goes to stdout (Markdown); ``--csv`` also writes one row per day. A
vertiport's capacity from its config alone, with no day played, is ``marl-vertiport capacity``
(:mod:`agents.studies.capacity`).
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from agents.controllers.episode import run_episode
from agents.controllers.registry import AgentSpecError, agent_help, make_controller
from agents.common.seeds import VALIDATION_SEED_BASE, parse_seed_range
from marl_vertiport import ConfigError, vertiport_v1
from marl_vertiport.sim.schema import ON_CHARGER


@dataclass
class ChargerDay:
    """One day's account of the charging ports (minutes summed over the ports)."""

    seed: int
    fleet_size: int
    approach_min: float = 0.0
    charging_min: float = 0.0
    parked_full_min: float = 0.0
    free_min: float = 0.0
    delivered_pct: float = 0.0
    sessions: int = 0
    vehicles_lost: int = 0


def charger_day(agent: str, config: str, fleet_size: int, seed: int,
                overrides: dict | None = None) -> ChargerDay:
    """Run one day of ``agent`` and account for the charging ports' minutes and energy: before
    each step, who is on each charger and in what state; after it, the battery they gained."""
    env = vertiport_v1.env(config=config, fleet_size=fleet_size, **(overrides or {}))
    sim = env.unwrapped.sim
    chargers = sim._charging_nodes.tolist()
    day = ChargerDay(seed=seed, fleet_size=fleet_size)
    minutes = sim.minutes_per_step
    last_occupant = {c: -1 for c in chargers}
    step: dict = {}

    def before_step(_agent: str, _obs: dict, _env) -> None:
        step["battery"], step["on_it"] = sim.battery.copy(), []
        for c in chargers:
            v = int(sim.node_occupant[c])
            if v < 0:
                day.free_min += minutes
            elif sim.status[v] != ON_CHARGER:
                day.approach_min += minutes
            elif step["battery"][v] >= 100.0:
                day.parked_full_min += minutes
            else:
                day.charging_min += minutes
                step["on_it"].append(v)
            if v >= 0 and v != last_occupant[c]:
                day.sessions += 1
            last_occupant[c] = v

    def after_step(_agent: str, _action: int, _env) -> None:
        before = step["battery"]
        day.delivered_pct += float(sum(max(sim.battery[v] - before[v], 0.0) for v in step["on_it"]))

    episode = run_episode(env, make_controller(agent), seed, before_step=before_step,
                          after_step=after_step)
    env.close()
    day.vehicles_lost = int(episode["stranded_air"] + episode["stranded_ground"])
    return day


def summarise(days: list[ChargerDay]) -> dict[str, float]:
    """Means over days of every field of :class:`ChargerDay` (but the seed)."""
    keys = [k for k in asdict(days[0]) if k != "seed"]
    return {k: float(np.mean([getattr(d, k) for d in days])) for k in keys}


def table(rows: list[dict[str, float]]) -> str:
    """A Markdown table of :func:`summarise` rows, one per fleet size."""
    head = ("| eVTOLs | approach (min) | charging (min) | parked full (min) | free (min) | "
            "delivered (%/day) | sessions | % per session | vehicles lost/day |")
    lines = [head, "|" + "---:|" * 9]
    for r in rows:
        per = r["delivered_pct"] / r["sessions"] if r["sessions"] else 0.0
        lines.append(f"| {r['fleet_size']:.0f} | {r['approach_min']:.0f} | {r['charging_min']:.0f} | "
                     f"{r['parked_full_min']:.0f} | {r['free_min']:.0f} | {r['delivered_pct']:.0f} | "
                     f"{r['sessions']:.0f} | {per:.0f} | {r['vehicles_lost']:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None, prog: str = "python -m agents.studies.charger_study") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--agent", default="dispatcher",
                        help=f"controller: {agent_help()} (default: dispatcher)")
    parser.add_argument("--config", default="paper", help="env config (default: paper)")
    parser.add_argument("--fleet", type=int, nargs="+", default=[3, 4, 5],
                        help="fleet sizes to compare (default: 3 4 5)")
    parser.add_argument("--seeds", default=f"{VALIDATION_SEED_BASE}:{VALIDATION_SEED_BASE + 20}",
                        help="seed range START:STOP (default: the first 20 validation seeds)")
    parser.add_argument("--csv", type=Path, help="also write one row per day to this CSV file")
    args = parser.parse_args(argv)
    try:
        seeds = parse_seed_range(args.seeds)
        if min(args.fleet) < 1:
            raise ValueError(f"--fleet: fleet sizes must be >= 1, got {args.fleet}")
        days = {n: [] for n in args.fleet}
        for n in args.fleet:
            for k, seed in enumerate(seeds):
                days[n].append(charger_day(args.agent, args.config, n, seed))
                print(f"\r{args.agent}, {n} eVTOLs: day {k + 1}/{len(seeds)}", end="",
                      file=sys.stderr, flush=True)
            print(file=sys.stderr)
    except (ValueError, ConfigError, AgentSpecError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.agent} on {args.config}, seeds {seeds.start}-{seeds.stop - 1}; minutes a day "
          "summed over the charging ports, means over days:\n")
    print(table([summarise(days[n]) for n in args.fleet]))
    if args.csv is not None:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        rows = [asdict(d) for n in args.fleet for d in days[n]]
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
