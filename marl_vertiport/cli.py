"""Command line: ``python -m marl_vertiport.cli <command>`` (``--help`` on each command).

Commands:
    demo          run episodes with random legal actions; print metrics and steps per second
    info          print the spaces, feature columns and action names of a config
    check-config  validate a config file and print it resolved
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import yaml

from marl_vertiport.config import ConfigError, load_config, to_dict


def _demo(args: argparse.Namespace) -> int:
    from marl_vertiport import vertiport_v1

    env = vertiport_v1.env(config=args.config)
    rng = np.random.default_rng(args.seed)
    for episode in range(args.episodes):
        env.reset(seed=args.seed + episode)
        steps, start = 0, time.perf_counter()
        total = env.unwrapped.config.schedule.episode_steps
        info: dict = {}
        for agent in env.agent_iter():
            obs, _, term, trunc, info = env.last()
            if term or trunc:
                env.step(None)
                continue
            env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
            steps += 1
            if steps % 240 == 0:
                print(f"\r  episode {episode}: minute {steps}/{total}", end="", file=sys.stderr)
        elapsed = time.perf_counter() - start
        print("\r", end="", file=sys.stderr)
        metrics = {k: v for k, v in info["episode"].items() if k != "action_counts"}
        print(f"episode {episode} (seed {args.seed + episode}): {steps} steps in {elapsed:.2f} s "
              f"({steps / elapsed:,.0f} steps/s)")
        print(json.dumps({k: round(float(v), 3) for k, v in metrics.items()}, indent=2))
    env.close()
    return 0


def _info(args: argparse.Namespace) -> int:
    from marl_vertiport.sim.schema import EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES
    from marl_vertiport.vertiport_v1 import raw_env

    env = raw_env(config=args.config)
    sim = env.sim
    print(f"config: {env.config.name}; {sim.n} eVTOLs; {sim.layout.n_normal} normal ports, "
          f"{sim.layout.n_charging} charging ports, {sim.layout.n_hover} hover spots, "
          f"{len(sim.layout.destination_xy_m)} destinations")
    print("actions:")
    for i, name in enumerate(sim.actions.names(sim.layout)):
        print(f"  {i:3d} {name}")
    print("port node features:", ", ".join(PORT_FEATURES))
    print("eVTOL node features:", ", ".join(EVTOL_FEATURES))
    print("self features:", ", ".join(SELF_FEATURES))
    print("observation space:", env.observation_space(env.possible_agents[0]))
    env.close()
    return 0


def _check_config(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    print(yaml.safe_dump(to_dict(cfg), sort_keys=False), end="")
    return 0


def main(argv: list[str] | None = None, prog: str = "python -m marl_vertiport.cli") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="random legal actions for a few episodes")
    demo.add_argument("--config", default="paper", help="config name or YAML path")
    demo.add_argument("--episodes", type=int, default=1)
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_demo)
    info = sub.add_parser("info", help="spaces and action names of a config")
    info.add_argument("--config", default="paper")
    info.set_defaults(func=_info)
    check = sub.add_parser("check-config", help="validate a config and print it resolved")
    check.add_argument("config")
    check.set_defaults(func=_check_config)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
