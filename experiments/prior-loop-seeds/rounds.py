"""The round curve of a loop with the rule prior: each round's policy (played as the prior it
was fit as) against the dispatcher and against the round before, paired day by day on
validation days, for each training seed and for the seeds together.

Prints the round table (Markdown) to stdout and writes ``rounds.png`` into ``--folder``. Run
from the repository root; with no options it draws this study's curve
(experiments/prior-loop-seeds)::

    python experiments/prior-loop-seeds/rounds.py
    python experiments/prior-loop-seeds/rounds.py --folder experiments/prior-actor-proposes \\
        --runs 'runs/ei_actor_s{seed}' --fits 5 --title 'the actor proposing alone'
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from agents.evaluate.stats import bootstrap_ci  # noqa: E402

HERE = Path(__file__).parent
#: The start is the shipped policy played as round 0's driver (the dispatcher as its prior at
#: the loops' weight, 2), the same for every seed; its rows are in this study's validation.csv.
START = "prior[weight=2]"
CASES = {"paper": "case 1", "paper_uncertain": "case 2", "paper_uncertain_10": "10 %"}


class Curve:
    """Which policies make the curve: fits ``0 .. fits-1`` of the runs ``runs.format(seed=s)``."""

    def __init__(self, runs: str, fits: int, seeds: tuple[int, ...]) -> None:
        self.runs, self.seeds = runs, seeds
        self.stages = ("start", *(f"fit {k}" for k in range(fits)))

    def agent(self, stage: str, seed: int) -> str:
        """The agent name in the validation rows of ``stage``'s policy of training seed ``seed``."""
        if stage == "start":
            return START
        return f"prior[policy={self.runs.format(seed=seed)}/model_fit{stage.split()[1]}.pt]"


def _cell(diff: pd.Series) -> str:
    low, high = bootstrap_ci(diff.to_numpy())
    return f"{diff.mean():+.0f} [{low:+.0f}, {high:+.0f}]".replace("-", "\u2212")


def table(curve: Curve, reward: pd.DataFrame, lost: pd.DataFrame) -> str:
    """Markdown rows: per seed and stage, the gain over the dispatcher by case and over all
    days, the step over the stage before, and vehicles lost a day by case. A stage whose
    policy some seed lacks is left out of the seeds' mean."""
    lines = ["| seed | policy | case 1 | case 2 | 10 % | all days | − the round before | lost a day (1 / 2 / 10 %) |",
             "|---|---|---:|---:|---:|---:|---:|---|"]
    base = reward["dispatcher"]
    lines.append("| | dispatcher | " + " | ".join(f"{base.loc[c].mean():.0f}" for c in CASES)
                 + f" | {base.mean():.0f} | | "
                 + " / ".join(f"{lost['dispatcher'].loc[c].mean():.2f}" for c in CASES) + " |")
    for seed in (*curve.seeds, "all"):
        seeds = curve.seeds if seed == "all" else (seed,)

        def have(stage: str) -> bool:
            return all(curve.agent(stage, s) in reward for s in seeds)

        def mean(frame: pd.DataFrame, stage: str) -> pd.Series:
            return sum(frame[curve.agent(stage, s)] for s in seeds) / len(seeds)

        for k, stage in enumerate(curve.stages):
            if not have(stage) or (stage == "start" and seed != curve.seeds[0]):
                continue  # the start is the same for every seed
            gains = mean(reward, stage) - base
            before = curve.stages[k - 1] if k else None
            step = (mean(reward, stage) - mean(reward, before)
                    if before is not None and have(before) else None)
            label = "" if stage == "start" else str(seed)
            cases = " | ".join(_cell(gains.loc[c]) for c in CASES)
            lines.append(f"| {label} | {stage} | {cases} | {_cell(gains)} | "
                         f"{_cell(step) if step is not None else ''} | "
                         + " / ".join(f"{mean(lost, stage).loc[c].mean():.2f}" for c in CASES) + " |")
    return "\n".join(lines)


def plot(curve: Curve, reward: pd.DataFrame, title: str, out: Path) -> None:
    """The curve: gain over the dispatcher (all days, 95 % CI) by stage, a line per seed."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, seed in enumerate(curve.seeds):
        x = [i for i, stage in enumerate(curve.stages) if curve.agent(stage, seed) in reward]
        gains = [reward[curve.agent(curve.stages[i], seed)] - reward["dispatcher"] for i in x]
        mean = [g.mean() for g in gains]
        low, high = zip(*(bootstrap_ci(g.to_numpy()) for g in gains))
        ax.errorbar(np.array(x) + (k - 1) * 0.06, mean,
                    yerr=[np.subtract(mean, low), np.subtract(high, mean)],
                    marker="o", capsize=3, label=f"training seed {seed}")
    ax.axhline(0, color="grey", lw=1)
    ax.set_xticks(np.arange(len(curve.stages)), list(curve.stages))
    ax.set_ylabel("policy (as its prior) − dispatcher, reward a day")
    days = reward.index.get_level_values("seed")
    ax.set_title(f"Expert iteration with the rule prior{title}, round by round\n(validation "
                 f"days {days.min()}-{days.max()}, three cases)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--folder", type=Path, default=HERE,
                        help="the study: its validation.csv is read, rounds.png written there")
    parser.add_argument("--runs", default="runs/ei_prior_s{seed}",
                        help="the run folders as named in the rows, with {seed}")
    parser.add_argument("--fits", type=int, default=3, help="fits 0 .. FITS-1 of each run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--title", default="", help="what sets this loop apart, for the plot")
    args = parser.parse_args()
    curve = Curve(args.runs, args.fits, tuple(args.seeds))
    # The dispatcher's and the start's rows are this study's; another study adds its fits'.
    files = [HERE / "validation.csv"] + ([args.folder / "validation.csv"]
                                         if args.folder.resolve() != HERE.resolve() else [])
    days = pd.concat([pd.read_csv(f) for f in files])
    days["lost"] = days.stranded_air + days.stranded_ground
    reward = days.pivot_table(index=["config", "seed"], columns="agent", values="total_reward")
    lost = days.pivot_table(index=["config", "seed"], columns="agent", values="lost")
    plot(curve, reward, f", {args.title}" if args.title else "", args.folder / "rounds.png")
    print(table(curve, reward, lost))


if __name__ == "__main__":
    main()
