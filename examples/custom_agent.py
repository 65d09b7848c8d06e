"""A controller of your own, run through the plain AEC loop and then through the evaluation.

    python examples/custom_agent.py [DAYS] [OUT]     # 4 days, into runs/eval_custom by default
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # so `examples` imports

from agents.controllers.base import CHARGING_PORT, Observation
from agents.evaluate import main as evaluate
from marl_vertiport import vertiport_v1


class ChargeFirst:
    """Land on the charger when it is free, take off when charged and due, else wait."""

    def act(self, observation: dict) -> int:
        obs = Observation(observation)  # named access to the graph features
        if obs.mask[obs.avoid] and obs.mine("conflict"):
            return obs.avoid
        if obs.mask[obs.takeoff] and obs.mine("battery_pct") > 70 and obs.mine("minutes_to_schedule") <= 0:
            return obs.takeoff
        chargers = [n for n in obs.free_nodes(CHARGING_PORT) if obs.mask[obs.go_to(n)]]
        if chargers and obs.mine("battery_pct") < 90:
            return obs.go_to(chargers[0])
        if obs.mask[obs.stay]:
            return obs.stay
        if obs.mask[obs.continue_]:
            return obs.continue_
        return int(obs.mask.argmax())  # the ATC clears only landings: take the first one


if __name__ == "__main__":
    env, agent = vertiport_v1.env(config="paper"), ChargeFirst()
    env.reset(seed=0)
    for name in env.agent_iter():
        observation, reward, termination, truncation, info = env.last()
        env.step(None if termination or truncation else agent.act(observation))
    print("one day:", {k: round(v, 1) for k, v in info["episode"].items() if k != "action_counts"})
    days = sys.argv[1] if len(sys.argv) > 1 else "4"
    out = sys.argv[2] if len(sys.argv) > 2 else "runs/eval_custom"
    sys.exit(evaluate(["--agents", "examples.custom_agent:ChargeFirst", "fcfs", "--episodes", days,
                       "--out", out]))
