"""Is a fresh training run the policy the docs describe? ``marl-vertiport check-train``.

On the machine it was made on, ``make train`` gives the shipped checkpoint bit for bit. On
another machine it cannot: torch picks its float kernels by the CPU's vector instructions, the
sums come out in another order, and training carries the last-bit differences on until the
weights differ by a few per cent (docs/training.md, "Reproducibility"). What a user can check
there is the quality: this command trains the default config with its seed (as ``make train``
does), plays the new checkpoint and the shipped one on the same 200 validation days
(``configs/checks/train.yaml``) and pairs them day by day::

    make check-train                                             # train, then compare
    marl-vertiport check-train --checkpoint runs/train/default_x/model_59.pt   # a finished run
    marl-vertiport check-train --margin A.pt B.pt C.pt           # measure M from 3 seeds' runs
    make check-train-margin                                      # train seeds 0-2, measure M

**Equivalent** means: the 95 % bootstrap interval of the mean daily reward difference lies
within ±M, and the vehicles lost a day (in the air and on the ground) differ by at most the
config's ``lost_margin``. M and ``lost_margin`` are the spreads of the mean daily reward and of
the vehicles lost a day between training seeds of the same pipeline on the same days, measured
on one machine and written in ``configs/checks/train.yaml``: a run on
another machine is, in effect, another seed, and a policy within the spread of the seeds is as
good as the docs' policy can be told to be. The command prints M, a table of every safety
metric beside the reward, and the verdict; ``check.json`` and the evaluation's files go to
``--out``. Exit codes: 0 equivalent, 1 not equivalent, 2 bad input, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.common.seeds import parse_seed_range
from agents.controllers.registry import SHIPPED_CHECKPOINT

PROG = "python -m agents.checks.train"
CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "checks"
#: Metrics compared day by day: the reward and every safety metric beside it.
METRICS = ("total_reward", "stranded", "stranded_air", "stranded_ground", "collisions",
           "separation_losses", "contacts", "completed_trips")
LABELS = {"total_reward": "reward a day", "stranded": "vehicles lost a day (air + ground)",
          "stranded_air": "  lost in the air", "stranded_ground": "  lost on the ground",
          "collisions": "unresolved conflicts (S = -5)", "separation_losses": "losses of separation",
          "contacts": "contacts", "completed_trips": "completed trips"}


class CheckError(ValueError):
    """Bad input: a missing checkpoint, a broken check config; nothing was run."""


@dataclass(frozen=True)
class EquivalenceConfig:
    """``configs/checks/train.yaml``: what is trained, on which days it is compared, the bounds."""

    train_config: str = "default"
    """The train config ``make train`` runs."""
    seed: int = 0
    """Its training seed (the shipped checkpoint's)."""
    configs: tuple[str, ...] = ("paper", "paper_uncertain", "small", "twin", "wide")
    """The cases the days are played on (the training scenarios)."""
    seeds: str = "800200:800240"
    """Validation seeds ``START:STOP``, played on every case."""
    reward_margin: float = 0.0
    """M: the spread of the mean daily reward between training seeds on these days."""
    lost_margin: float = 0.1
    """The most the vehicles lost a day may differ."""
    margin_note: str = ""
    """How M was measured (seeds, their means, machine, command)."""

    def __post_init__(self) -> None:
        from marl_vertiport.config import ConfigError

        try:
            parse_seed_range(self.seeds)
        except ValueError as exc:
            raise ConfigError(f"seeds: {exc}") from None
        if not self.configs:
            raise ConfigError("configs: at least one case")
        if not (self.reward_margin >= 0 and math.isfinite(self.reward_margin)):
            raise ConfigError("reward_margin: must be a finite number >= 0")
        if not self.lost_margin >= 0:
            raise ConfigError("lost_margin: must be >= 0")


def load_check_config(spec: str | Path = "train") -> EquivalenceConfig:
    from marl_vertiport.config import ConfigError, load_yaml_dataclass

    try:
        return load_yaml_dataclass(EquivalenceConfig, spec, CONFIG_DIR, "check config")
    except ConfigError as exc:
        raise CheckError(str(exc)) from None


def _shown(path: str | Path) -> str:
    """``path`` relative to the working directory when it lies below it."""
    try:
        return Path(path).resolve().relative_to(Path.cwd()).as_posix()
    except ValueError:
        return str(path)


def checkpoint_of(path: str) -> str:
    """A checkpoint file, or a training run's folder (its last checkpoint)."""
    given = Path(path)
    if given.is_dir():
        from agents.training.checkpoints import latest_checkpoint

        found = latest_checkpoint(given)
        if found is None:
            raise CheckError(f"{path}: a folder without a checkpoint (model_<iteration>.pt)")
        return str(found)
    if not given.is_file():
        raise CheckError(f"checkpoint {path}: no such file or run folder")
    return path


# ------------------------------------------------------------------------------ weights
def weight_difference(a: str | Path, b: str | Path) -> dict[str, Any]:
    """How far the actor and critic weights of two checkpoints are apart: ``identical``, the
    largest absolute difference and the norm of the difference over the norm of ``b``'s."""
    from agents.controllers.gcn import read_checkpoint

    da, db = read_checkpoint(a), read_checkpoint(b)
    out: dict[str, Any] = {}
    for part in ("actor_state_dict", "critic_state_dict"):
        wa, wb = da.get(part) or {}, db.get(part) or {}
        if wa.keys() != wb.keys() or any(wa[k].shape != wb[k].shape for k in wa):
            out[part] = {"identical": False, "comparable": False}
            continue
        identical = all(bool((wa[k] == wb[k]).all()) for k in wa)
        diff2 = sum(float(((wa[k].double() - wb[k].double()) ** 2).sum()) for k in wa)
        norm2 = sum(float((wb[k].double() ** 2).sum()) for k in wb)
        largest = max((float((wa[k].double() - wb[k].double()).abs().max()) for k in wa),
                      default=0.0)
        out[part] = {"identical": identical, "comparable": True, "max_abs": largest,
                     "relative_l2": math.sqrt(diff2 / norm2) if norm2 else 0.0}
    return out


def describe_weights(diff: dict[str, Any]) -> str:
    actor, critic = diff["actor_state_dict"], diff["critic_state_dict"]
    if actor["identical"] and critic["identical"]:
        return "bit-identical to the shipped checkpoint's (actor and critic)"
    if not actor.get("comparable"):
        return "not comparable with the shipped checkpoint's (another model size)"
    return (f"differ from the shipped checkpoint's: actor largest |difference| "
            f"{actor['max_abs']:.3g}, {100 * actor['relative_l2']:.2f} % of the weights' norm")


# ------------------------------------------------------------------------------ days
def play(agents: Sequence[str], cfg: EquivalenceConfig, backend, episodes: int | None = None,
         overrides: tuple = (), progress: bool = True):
    """Every agent on the check's days (the first ``episodes`` seeds per case when given)."""
    from agents.evaluate.run import evaluate
    from agents.evaluate.settings import EvalSettings

    days = parse_seed_range(cfg.seeds)
    n = len(days) if episodes is None else episodes
    settings = EvalSettings(agents=tuple(agents), configs=tuple(cfg.configs), episodes=n,
                            first_seed=days.start, overrides=overrides)
    return evaluate(settings, progress=progress, backend=backend)


def _by_day(evaluation, agent: str) -> dict[tuple[str, int], dict[str, Any]]:
    return {(r.task.config, r.task.seed): r.metrics for r in evaluation.records
            if r.task.agent == agent and r.metrics is not None}


def paired(evaluation, base: str, candidate: str) -> dict[str, dict[str, float]]:
    """Per metric of :data:`METRICS`: the mean a day of each, the mean difference (candidate -
    base) over the days both played and its 95 % bootstrap interval."""
    from agents.evaluate.stats import bootstrap_ci

    a, b = _by_day(evaluation, base), _by_day(evaluation, candidate)
    days = sorted(set(a) & set(b))
    if not days:
        raise CheckError(f"{base} and {candidate} played no day in common")
    out = {}
    for metric in METRICS:
        diff = np.array([float(b[d][metric]) - float(a[d][metric]) for d in days])
        low, high = bootstrap_ci(diff)
        out[metric] = {"base": float(np.mean([a[d][metric] for d in days])),
                       "candidate": float(np.mean([b[d][metric] for d in days])),
                       "difference": float(diff.mean()), "ci_low": low, "ci_high": high,
                       "days": len(days)}
    return out


def verdict(stats: dict[str, dict[str, float]], reward_margin: float,
            lost_margin: float) -> tuple[bool, list[str]]:
    """Equivalent when the reward difference's interval lies within ±``reward_margin`` and
    the vehicles lost a day differ by at most ``lost_margin``; the reasons either way."""
    reward, lost = stats["total_reward"], stats["stranded"]
    reasons = []
    inside = -reward_margin <= reward["ci_low"] and reward["ci_high"] <= reward_margin
    reasons.append(f"the reward difference's interval [{reward['ci_low']:+.0f}, "
                   f"{reward['ci_high']:+.0f}] {'lies' if inside else 'does not lie'} within "
                   f"±{reward_margin:.0f}")
    close = abs(lost["difference"]) <= lost_margin + 1e-12
    reasons.append(f"the vehicles lost a day differ by {lost['difference']:+.2f} "
                   f"({'within' if close else 'beyond'} ±{lost_margin:.2f})")
    return inside and close, reasons


def spread(evaluation, agents: Sequence[str]) -> dict[str, Any]:
    """M from several training seeds' checkpoints played on the same days: the largest
    difference of their mean daily rewards (and ``lost_margin``, that of their vehicles lost a
    day), with each one's mean reward and vehicles lost."""
    means = {}
    for agent in agents:
        days = _by_day(evaluation, agent)
        means[agent] = {"reward": float(np.mean([m["total_reward"] for m in days.values()])),
                        "lost": float(np.mean([m["stranded"] for m in days.values()])),
                        "days": len(days)}
    rewards = [m["reward"] for m in means.values()]
    lost = [m["lost"] for m in means.values()]
    return {"margin": max(rewards) - min(rewards), "lost_margin": max(lost) - min(lost),
            "runs": means}


# ------------------------------------------------------------------------------ output
def table(stats: dict[str, dict[str, float]], reward_margin: float, lost_margin: float) -> str:
    rows = [("metric (mean a day)", "shipped", "new", "new - shipped [95 % CI]", "bound")]
    for metric in METRICS:
        s = stats[metric]
        digits = {"total_reward": 0, "completed_trips": 1}.get(metric, 2)
        bound = (f"±{reward_margin:.0f}" if metric == "total_reward"
                 else f"±{lost_margin:.2f}" if metric == "stranded" else "")
        rows.append((LABELS[metric], f"{s['base']:.{digits}f}", f"{s['candidate']:.{digits}f}",
                     f"{s['difference']:+.{digits}f} [{s['ci_low']:+.{digits}f}, "
                     f"{s['ci_high']:+.{digits}f}]", bound))
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
             for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _days_text(cfg: EquivalenceConfig, evaluation) -> str:
    seeds = evaluation.settings.seeds
    n = len(evaluation.settings.configs) * len(seeds)
    return (f"{n} validation days: {', '.join(cfg.configs)} x seeds {seeds[0]}-{seeds[-1]}")


# ------------------------------------------------------------------------------ command
def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    from agents.execution import add_backend_arguments

    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--checkpoint", metavar="PATH",
                      help="compare this checkpoint (or a run folder's last one) instead of "
                           "training one")
    what.add_argument("--margin", nargs="+", metavar="PATH",
                      help="measure M instead: the checkpoints (or run folders) of two or more "
                           "training seeds of the pipeline, played on the check's days")
    parser.add_argument("--against", default=str(SHIPPED_CHECKPOINT), metavar="PATH",
                        help="the checkpoint to compare with (default: the shipped one)")
    parser.add_argument("--config", default="train", metavar="NAME",
                        help="the check's settings: a name in configs/checks/ or a YAML path "
                             "(default: train)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="folder for the run, the evaluation and check.json "
                             "(default: runs/check-train/<time>)")
    parser.add_argument("--episodes", type=int, default=None, metavar="N",
                        help="only the first N days of each case (a quick look: the verdict "
                             "then says it is not the check)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="env config override for every day (a quick "
                                                  "look, as --episodes)")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="local processes for the training's days and the evaluation "
                             "(default: the train config's, then every core)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_backend_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    import os

    from agents.evaluate.settings import InputError, parse_overrides
    from agents.execution import INTERRUPTED, BackendError, backend_from_args
    from marl_vertiport.config import ConfigError

    args_list = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(prog).parse_args(args_list)
    command = shlex.join([*prog.split(), *args_list])
    out = args.out or Path("runs/check-train") / time.strftime("%Y%m%d-%H%M%S")
    try:
        cfg = load_check_config(args.config)
        overrides = parse_overrides(args.overrides)
        if args.episodes is not None and not 1 <= args.episodes <= len(parse_seed_range(cfg.seeds)):
            raise CheckError(f"--episodes {args.episodes}: the check has "
                             f"{len(parse_seed_range(cfg.seeds))} days per case")
        if args.workers is not None and args.workers < 1:
            raise CheckError(f"--workers must be >= 1, got {args.workers}")
        args.against = checkpoint_of(args.against)
        args.margin = [checkpoint_of(p) for p in args.margin] if args.margin else None
        args.checkpoint = checkpoint_of(args.checkpoint) if args.checkpoint else None
        if args.margin is not None and len(args.margin) < 2:
            raise CheckError("--margin needs the checkpoints of two or more training seeds")
        quick = args.episodes is not None or bool(overrides)
    except (CheckError, ConfigError, InputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    if args.margin is not None:
        backend = backend_from_args(args, args.workers or os.cpu_count())
        with backend:
            evaluation = play(args.margin, cfg, backend, args.episodes, overrides,
                              not args.no_progress)
        if evaluation.error is not None:
            print(f"error: {evaluation.error}", file=sys.stderr)
            return 130 if evaluation.error == INTERRUPTED else 1
        result = spread(evaluation, args.margin)
        _write(out, evaluation, command, {"mode": "margin", "command": command,
                                          "days": _days_text(cfg, evaluation), **result})
        print(f"\n{_days_text(cfg, evaluation)}")
        for agent, m in result["runs"].items():
            print(f"  {agent}: reward {m['reward']:.1f} a day, vehicles lost {m['lost']:.2f} a day")
        print(f"M = {result['margin']:.1f} (the largest difference of the mean daily rewards), "
              f"lost_margin = {result['lost_margin']:.3f} (of the vehicles lost a day)"
              + ("; a quick look, not the check's days" if quick else ""))
        return 0

    started = time.time()
    candidate = args.checkpoint
    try:
        if candidate is None:
            from agents.training.config import load_train_config
            from agents.training.pipeline import train
            from marl_vertiport.config import build_dataclass, to_dict

            train_cfg = load_train_config(cfg.train_config)
            train_cfg = build_dataclass(type(train_cfg), {**to_dict(train_cfg), "seed": cfg.seed})
            with backend_from_args(args, args.workers or train_cfg.pretrain.workers) as backend:
                print(f"check-train: training {cfg.train_config} (seed {cfg.seed}) into "
                      f"{out / 'train'}, as make train does", flush=True)
                candidate = str(train(train_cfg, out / "train", evaluate=False, backend=backend))
        diff = weight_difference(candidate, args.against)
    except (ConfigError, ValueError, BackendError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    trained_s = time.time() - started
    backend = backend_from_args(args, args.workers or os.cpu_count())
    with backend:
        evaluation = play([args.against, candidate], cfg, backend, args.episodes, overrides,
                          not args.no_progress)
    if evaluation.error is not None:
        print(f"error: {evaluation.error}", file=sys.stderr)
        return 130 if evaluation.error == INTERRUPTED else 1
    stats = paired(evaluation, args.against, candidate)
    same, reasons = verdict(stats, cfg.reward_margin, cfg.lost_margin)
    word = "EQUIVALENT" if same else "NOT EQUIVALENT"
    if quick:
        word += " (a quick look on fewer or changed days, not the check)"
    report = {"mode": "compare", "command": command, "candidate": candidate,
              "against": args.against, "weights": diff, "days": _days_text(cfg, evaluation),
              "stats": stats, "reward_margin": cfg.reward_margin, "lost_margin": cfg.lost_margin,
              "margin_note": cfg.margin_note, "equivalent": same, "quick": quick,
              "verdict": word, "reasons": reasons,
              "seconds": {"training": trained_s, "evaluation": evaluation.seconds}}
    _write(out, evaluation, command, report)
    print(f"\ncheck-train: {_shown(candidate)} against {_shown(args.against)}")
    print(f"weights: {describe_weights(diff)}")
    print(f"days: {_days_text(cfg, evaluation)}, paired day by day")
    print(table(stats, cfg.reward_margin, cfg.lost_margin))
    print(f"M = {cfg.reward_margin:.0f}: {cfg.margin_note}")
    print(f"verdict: {word}: " + "; ".join(reasons))
    print(f"(written to {out}/check.json)")
    return 0 if same else 1


def _write(out: Path, evaluation, command: str, report: dict[str, Any]) -> None:
    from agents.evaluate.report import write_outputs

    out.mkdir(parents=True, exist_ok=True)
    write_outputs(evaluation, out / "eval", command)
    report = {**report, "provenance": evaluation.provenance}
    write_atomic(out / "check.json", json.dumps(report, indent=1, allow_nan=True) + "\n")


if __name__ == "__main__":
    sys.exit(main())
