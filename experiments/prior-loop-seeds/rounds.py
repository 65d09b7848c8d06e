"""The round curve of experiments/prior-loop-seeds: each round's policy (played as the prior it
was fit as) against the dispatcher and against the round before, paired day by day on the
validation days of validation.csv, for each training seed and for the three seeds together.

Writes rounds.png beside this file and prints the round table (Markdown) to stdout. Run from
the repository root: ``python experiments/prior-loop-seeds/rounds.py``."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from agents.evaluate.stats import bootstrap_ci  # noqa: E402

HERE = Path(__file__).parent
SEEDS = (0, 1, 2)
#: Stage label -> agent name in validation.csv, per training seed. The start is the shipped
#: policy played as round 0's driver (the dispatcher as its prior at the loop's weight, 2).
START = "prior[weight=2]"
STAGES = ("start", "fit 0", "fit 1", "fit 2")
CASES = {"paper": "case 1", "paper_uncertain": "case 2", "paper_uncertain_10": "10 %"}


def agent(stage: str, seed: int) -> str:
    """The name in validation.csv of ``stage``'s policy of training seed ``seed``."""
    if stage == "start":
        return START
    return f"prior[policy=runs/ei_prior_s{seed}/model_fit{stage[-1]}.pt]"


def _cell(diff: pd.Series) -> str:
    low, high = bootstrap_ci(diff.to_numpy())
    return f"{diff.mean():+.0f} [{low:+.0f}, {high:+.0f}]".replace("-", "\u2212")


def table(reward: pd.DataFrame, lost: pd.DataFrame) -> str:
    """Markdown rows: per seed and stage, the gain over the dispatcher by case and over all
    days, the step over the stage before, and vehicles lost a day by case."""
    lines = ["| seed | policy | case 1 | case 2 | 10 % | all days | − the round before | lost a day (1 / 2 / 10 %) |",
             "|---|---|---:|---:|---:|---:|---:|---|"]
    base = reward["dispatcher"]
    lines.append("| | dispatcher | " + " | ".join(f"{base.loc[c].mean():.0f}" for c in CASES)
                 + f" | {base.mean():.0f} | | "
                 + " / ".join(f"{lost['dispatcher'].loc[c].mean():.2f}" for c in CASES) + " |")
    for seed in (*SEEDS, "all"):
        seeds = SEEDS if seed == "all" else (seed,)

        def mean(frame: pd.DataFrame, stage: str) -> pd.Series:
            return sum(frame[agent(stage, s)] for s in seeds) / len(seeds)

        for k, stage in enumerate(STAGES):
            if stage == "start" and seed != SEEDS[0]:  # the start is the same for every seed
                continue
            gains = mean(reward, stage) - base
            step = mean(reward, stage) - mean(reward, STAGES[k - 1]) if k else None
            label = "" if stage == "start" else str(seed)
            cases = " | ".join(_cell(gains.loc[c]) for c in CASES)
            lines.append(f"| {label} | {stage} | {cases} | {_cell(gains)} | "
                         f"{_cell(step) if step is not None else ''} | "
                         + " / ".join(f"{mean(lost, stage).loc[c].mean():.2f}" for c in CASES) + " |")
    return "\n".join(lines)


def plot(reward: pd.DataFrame) -> None:
    """rounds.png: gain over the dispatcher (all days, 95 % CI) by stage, a line per seed."""
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(STAGES))
    for k, seed in enumerate(SEEDS):
        gains = [reward[agent(stage, seed)] - reward["dispatcher"] for stage in STAGES]
        mean = [g.mean() for g in gains]
        low, high = zip(*(bootstrap_ci(g.to_numpy()) for g in gains))
        ax.errorbar(x + (k - 1) * 0.06, mean, yerr=[np.subtract(mean, low), np.subtract(high, mean)],
                    marker="o", capsize=3, label=f"training seed {seed}")
    ax.axhline(0, color="grey", lw=1)
    ax.set_xticks(x, list(STAGES))
    ax.set_ylabel("policy (as its prior) − dispatcher, reward a day")
    days = reward.index.get_level_values("seed")
    ax.set_title(f"Expert iteration with the rule prior, round by round (validation days "
                 f"{days.min()}-{days.max()}, three cases)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "rounds.png", dpi=110)


def main() -> None:
    days = pd.read_csv(HERE / "validation.csv")
    days["lost"] = days.stranded_air + days.stranded_ground
    reward = days.pivot_table(index=["config", "seed"], columns="agent", values="total_reward")
    lost = days.pivot_table(index=["config", "seed"], columns="agent", values="lost")
    plot(reward)
    print(table(reward, lost))


if __name__ == "__main__":
    main()
