"""A soak: many days with every uncertainty high, across layouts and fleet sizes, checking the
invariants after every step and the memory of the process (``make soak``)::

    python -m agents.studies.soak --days 40 --configs paper small mid twin wide large

Each layout's env is built once and reused for all its days, as a long evaluation or training
run does, so that a leak shows as resident memory (RSS) that grows after the warm-up. Days
alternate between the controllers (random legal actions and the dispatcher by default, any
agent spec of the registry), on validation seeds. Exit code 0 when every invariant held and
RSS stayed within ``--rss-slack-mb`` of its level after the warm-up, 1 otherwise; the report
says what was covered.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

from agents.common.seeds import VALIDATION_SEED_BASE
from agents.controllers.episode import run_aec_episode
from agents.controllers.registry import make_controller
from marl_vertiport import ConfigError, vertiport_v1
from marl_vertiport.sim.invariants import violations

#: Every uncertainty well above the paper's 5 %.
HIGH = {"uncertainty.wind_gust_prob": 0.3, "uncertainty.charger_failure_prob": 0.3,
        "uncertainty.takeoff_failure_prob": 0.3, "uncertainty.action_misread_prob": 0.1,
        "uncertainty.position_noise_mean_m": 0.5, "uncertainty.position_noise_std_m": 1.0}


def rss_mb() -> float:
    """Resident memory of this process (MB), from /proc (Linux); NaN elsewhere."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def soak_day(env, agent: str, seed: int, events: Counter) -> list[str]:
    """One day; the invariant violations found (with the minute), counting what happened."""
    sim = env.unwrapped.sim
    problems: list[str] = []

    def check(name: str, _action: int, _env) -> None:
        info = env.infos[name]
        events["steps"] += 1
        for key in ("gusts", "charger_failures", "battery_depletions", "separation_losses",
                    "contacts", "touchdowns"):
            events[key] += int(info.get(key, 0))
        events["takeoff_failures"] += int(info.get("takeoff_failed", False))
        events["misreads"] += int(info.get("action") != info.get("commanded_action"))
        found = violations(sim, env.rewards[name])
        if found and len(problems) < 20:
            problems.extend(f"minute {sim.minute:g}: {p}" for p in found)

    run_aec_episode(env, make_controller(agent), seed, on_step=check)
    return problems


def main(argv: list[str] | None = None, prog: str = "python -m agents.studies.soak") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--days", type=int, default=40, help="days per layout (default: 40)")
    parser.add_argument("--configs", nargs="+", default=["paper", "small", "mid", "twin", "wide", "large"],
                        help="env configs, each with every uncertainty high")
    parser.add_argument("--agents", nargs="+", default=["random", "dispatcher"],
                        help="controllers, taking the days in turn (default: random dispatcher)")
    parser.add_argument("--rss-slack-mb", type=float, default=50.0,
                        help="allowed RSS growth after the warm-up, MB (default: 50)")
    args = parser.parse_args(argv)
    if args.days < 2:
        print("error: --days must be >= 2 (the first ones warm up)", file=sys.stderr)
        return 2
    try:
        envs = {c: vertiport_v1.env(config=c, **HIGH) for c in args.configs}
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    start, failures = time.time(), []
    events: Counter = Counter()
    warm = max(1, args.days // 10)
    rss_after_warmup = rss_now = float("nan")
    total = args.days * len(envs)
    for day in range(args.days):
        for config, env in envs.items():
            agent = args.agents[day % len(args.agents)]
            seed = VALIDATION_SEED_BASE + 10_000 + day
            found = soak_day(env, agent, seed, events)
            failures += [f"{config}, {agent}, seed {seed}, {p}" for p in found]
            events["days"] += 1
        rss_now = rss_mb()
        if day + 1 == warm:
            rss_after_warmup = rss_now
        print(f"\rsoak: {events['days']}/{total} days, {events['steps']:,} steps, RSS {rss_now:.0f} MB, "
              f"{len(failures)} violations", end="", file=sys.stderr)
    print(file=sys.stderr)
    for env in envs.values():
        env.close()
    growth = rss_now - rss_after_warmup
    fleets = ", ".join(f"{c} ({e.unwrapped.sim.n} eVTOLs)" for c, e in envs.items())
    levels = ", ".join(f"{key.split('.')[1]} {value}" for key, value in HIGH.items())
    print(f"soak: {events['days']} days ({args.days} per layout: {fleets}), {events['steps']:,} steps "
          f"in {time.time() - start:.0f} s, controllers {' and '.join(args.agents)}, every "
          f"uncertainty high ({levels})")
    print("covered: " + ", ".join(f"{events[k]:,} {k.replace('_', ' ')}" for k in (
        "gusts", "charger_failures", "takeoff_failures", "misreads", "battery_depletions",
        "separation_losses", "contacts", "touchdowns")))
    print(f"invariants: {'all held' if not failures else f'{len(failures)} violations'}; RSS "
          f"{rss_after_warmup:.0f} MB after {warm} warm-up day(s) per layout, {rss_now:.0f} MB at the end "
          f"({growth:+.1f} MB, allowed {args.rss_slack_mb:g})")
    for line in failures[:20]:
        print(f"  {line}")
    return 0 if not failures and not growth > args.rss_slack_mb else 1


if __name__ == "__main__":
    sys.exit(main())
