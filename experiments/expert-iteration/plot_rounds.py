"""The round curve of experiments/expert-iteration: each round's policy alone against the
dispatcher, paired day by day on the validation days of episodes.csv, per case (95 % bootstrap
intervals), into rounds.png. Run from the repository root:
``python experiments/expert-iteration/plot_rounds.py``."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from agents.evaluate.stats import bootstrap_ci  # noqa: E402

HERE = Path(__file__).parent
ROUNDS = {"shipped (round 0's driver)": "gcn",
          "fit 0": "runs/ei_paper_s0/model_fit0.pt",
          "fit 1": "runs/ei_paper_s0/model_fit1.pt",
          "fit 2": "runs/ei_paper_s0/model_fit2.pt",
          "fit 3": "runs/ei_r4/model_fit3.pt",
          "round 3, own labels": "runs/ei_paper_leg2/model_round3.pt"}
CASES = {"paper": "case 1", "paper_uncertain": "case 2", "paper_uncertain_10": "10 %"}


def main() -> None:
    days = pd.read_csv(HERE / "episodes.csv")
    days = days[days.seed.between(803000, 803029)]
    reward = days.pivot_table(index=["config", "seed"], columns="agent", values="total_reward")
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(ROUNDS))
    for k, (config, label) in enumerate(CASES.items()):
        rows = reward.loc[config]
        gains = [rows[agent] - rows["dispatcher"] for agent in ROUNDS.values()]
        mean = [g.mean() for g in gains]
        low, high = zip(*(bootstrap_ci(g.to_numpy()) for g in gains))
        ax.errorbar(x + (k - 1) * 0.08, mean, yerr=[np.subtract(mean, low), np.subtract(high, mean)],
                    marker="o", capsize=3, label=label)
    ax.axhline(0, color="grey", lw=1)
    ax.set_xticks(x, list(ROUNDS), fontsize=8)
    ax.set_ylabel("policy alone − dispatcher, reward a day")
    ax.set_title("Expert iteration: the policy alone, round by round (validation days 803000-803029)",
                 fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "rounds.png", dpi=110)


if __name__ == "__main__":
    main()
