"""Is the env as fast as another checkout's? ``python -m agents.bench.compare --base PATH``
(``make bench-compare BASE=PATH``).

A controller's traffic (the dispatcher's by default: the load the env exists for) is recorded
once, here; then the same actions are replayed through the AEC env of this checkout and of the
checkout at ``--base`` (a ``git worktree`` of another commit, say), each in a process of its own
(:mod:`agents.bench.replay`), ``--repeats`` times, the two interleaved (their order alternating
from round to round) so that a drift of the machine's speed falls on both alike. It prints the
median steps per second of each and their ratio; ``--out`` writes them as JSON. A refactor that
must not slow the env is held to a ratio of at least 0.97.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from agents.common.provenance import REPO_ROOT

REPLAY = Path(__file__).with_name("replay.py")


def run_replay(root: Path, traffic_file: Path) -> dict:
    """One timed replay with the env of checkout ``root``."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run([sys.executable, str(REPLAY), str(traffic_file)], cwd=root, env=env,
                         capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        raise RuntimeError(f"replay in {root} failed: {out.stderr.strip().splitlines()[-1:]}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if not Path(result["env"]).resolve().is_relative_to(root.resolve()):
        raise RuntimeError(f"the replay for {root} ran the env at {result['env']}")
    return result


def compare(base: Path, agent: str, config: str, days: int, repeats: int, seed: int,
            log=print) -> dict:
    from agents.bench.env import record_traffic

    traffic = {"config": config, "seed": seed, "days": record_traffic(agent, config, days, seed)}
    with tempfile.TemporaryDirectory() as tmp:
        traffic_file = Path(tmp) / "traffic.json"
        traffic_file.write_text(json.dumps(traffic))
        runs: dict[str, list[float]] = {"base": [], "this": []}
        sides = {"base": base, "this": REPO_ROOT}
        for r in range(repeats):
            order = ("base", "this") if r % 2 == 0 else ("this", "base")
            for side in order:
                runs[side].append(run_replay(sides[side], traffic_file)["steps_per_s"])
            log(f"  round {r + 1}/{repeats}: base {runs['base'][-1]:,.0f}, this "
                f"{runs['this'][-1]:,.0f} steps/s")
    medians = {side: statistics.median(rates) for side, rates in runs.items()}
    return {"agent": agent, "config": config, "days": days, "seed": seed, "repeats": repeats,
            "steps": sum(len(d) for d in traffic["days"]), "base": str(base),
            "runs": runs, "median_steps_per_s": medians,
            "ratio": medians["this"] / medians["base"]}


def main(argv: list[str] | None = None, prog: str = "python -m agents.bench.compare") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", type=Path, required=True,
                        help="the other checkout (e.g. a git worktree of the commit before)")
    parser.add_argument("--agent", default="dispatcher", help="whose traffic (default: dispatcher)")
    parser.add_argument("--config", default="paper", help="env config (default: paper)")
    parser.add_argument("--days", type=int, default=4, help="days of traffic (default: 4)")
    parser.add_argument("--repeats", type=int, default=5, help="timed replays of each (default: 5)")
    parser.add_argument("--seed", type=int, default=2000, help="first day's seed (default: 2000)")
    parser.add_argument("--out", type=Path, default=None, help="also write the result as JSON")
    args = parser.parse_args(argv)
    if not (args.base / "marl_vertiport" / "vertiport_v1.py").is_file():
        print(f"error: --base {args.base}: not a checkout of this project", file=sys.stderr)
        return 2
    result = compare(args.base, args.agent, args.config, args.days, args.repeats, args.seed)
    med = result["median_steps_per_s"]
    print(f"{args.agent} traffic on {args.config}, {result['steps']:,} steps, median of "
          f"{args.repeats}: this checkout {med['this']:,.0f} steps/s, base {med['base']:,.0f} "
          f"steps/s; ratio {result['ratio']:.3f}")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
