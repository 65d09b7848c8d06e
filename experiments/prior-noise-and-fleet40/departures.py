"""Where a policy with the dispatcher as its prior departs from the dispatcher on one day: the
decisions with a choice where the two differ, counted by the vehicle's status and by the kind
of action each chose (stay, take off, move or land on a port, go to a hover spot, continue,
avoid), with the day's vehicles lost. Run from the repository root, e.g.::

    python experiments/prior-noise-and-fleet40/departures.py \\
        'prior[policy=runs/ei_prior_s0/model_fit2.pt]' fleet40 803200

Validation days only: the day is the scenario's seed, and this is a diagnosis, not a result."""

import argparse
import collections

import numpy as np
import torch

from agents.controllers.episode import action_names, run_episode
from agents.controllers.registry import make_controller
from marl_vertiport.config import load_config
from marl_vertiport.gym_env import VertiportEnv

STATUS = ("on_port", "on_charger", "hovering", "taxiing", "departing", "away", "arriving",
          "out_of_service")


def kind(name: str) -> str:
    """The kind of an action from its name: ``normal_port_3`` and ``charging_port_0`` are
    ports, ``hover_spot_2`` a hover spot; ``stay``, ``takeoff``, ``continue`` and
    ``avoid_collision`` are their own."""
    if name.startswith(("normal_port_", "charging_port_")):
        return "port"
    if name.startswith("hover_spot"):
        return "hover spot"
    return name


class Recorder:
    """``controller`` as the episode loop's policy, recording its choice and its rule's."""

    def __init__(self, controller, names: list[str]) -> None:
        self.controller, self.names = controller, names
        self.departures: collections.Counter = collections.Counter()
        self.decisions = 0

    def bind(self, sim) -> None:
        self.controller.bind(sim)

    def reset(self, seed=None) -> None:
        self.controller.reset(seed=seed)

    def act(self, obs: dict) -> int:
        chosen = int(self.controller.act(obs))
        if int(np.sum(obs["action_mask"])) > 1:
            self.decisions += 1
            rule = self.controller.last_rule  # the rule's choice the prior weighed
            if rule != chosen:
                status = STATUS[int(obs["observation"]["self"][0])]
                self.departures[(status, kind(self.names[rule]), kind(self.names[chosen]))] += 1
        return chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("agent", help="a prior spec, e.g. 'prior[policy=runs/x/model_fit2.pt]'")
    parser.add_argument("config", help="an env config name, e.g. fleet40")
    parser.add_argument("seed", type=int, help="a validation day (800000-999999)")
    args = parser.parse_args()
    if not 800_000 <= args.seed < 1_000_000:
        parser.error(f"seed {args.seed}: use a validation day, 800000-999999")
    torch.set_num_threads(1)
    controller = make_controller(args.agent)
    if not hasattr(controller, "rule"):
        parser.error(f"{args.agent!r} has no rule to depart from (use a prior[...] spec)")
    env = VertiportEnv(config=load_config(args.config))
    recorder = Recorder(controller, action_names(env))
    metrics = run_episode(env, recorder, args.seed)
    print(f"{args.agent} on {args.config}, day {args.seed}: reward {metrics['total_reward']:.0f}, "
          f"vehicles lost {metrics['stranded_air']} in the air and {metrics['stranded_ground']} "
          f"on the ground; {sum(recorder.departures.values())} departures from the rule in "
          f"{recorder.decisions} decisions with a choice")
    print("| status | the rule | the policy | departures |\n|---|---|---|---:|")
    for (status, rule, chosen), count in recorder.departures.most_common():
        print(f"| {status} | {rule} | {chosen} | {count} |")


if __name__ == "__main__":
    main()
