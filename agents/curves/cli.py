"""Learning curves over training seeds: train N seeds of each train config and draw the paper's
total reward (and vehicles lost, unresolved conflicts) per training day against environment
steps, with 95 % bootstrap intervals over seeds (mean and interquartile mean) and the baselines
as horizontal lines.

Usage::

    python -m agents.curves                                   # scratch, 3 seeds (make curves)
    python -m agents.curves --configs scratch configs/train/ppo_stage/long.yaml --seeds 3
    python -m agents.curves --configs scratch --seeds 2 --iterations 2 --baseline-episodes 0
    python -m agents.curves --configs scratch --backend ray --ray-address auto

Each (config, seed) is one training run in ``<out>/runs/<config>_seed<S>/`` (its configs,
checkpoints and ``curves.csv``), run as a task of the execution layer: ``--workers`` local
processes (default 2), or Ray (``--backend ray``). Seeds ``--first-seed`` .. ``+ --seeds - 1``
are the train configs' ``seed``: a run is reproducible from its config and seed. The baselines
play validation days (never test days). Outputs in ``--out`` (default
``runs/curves/<configs>``): ``curves.csv`` (one row per config, seed and iteration),
``summary.csv``, ``baselines.csv``, ``curves.png`` and ``curves.json`` (configs, seeds, run
folders, wall times). With ``--resume`` a run whose folder in ``--out`` already holds a checkpoint
of the same config goes on from its last checkpoint (``--iterations`` may extend a finished
run), so that a long budget can be trained over several sittings; the others start afresh.
A resumed run's later iterations are not bit for bit those of an unbroken run (its env copies
start new days), and its wall time in ``curves.json`` is that of the last sitting (each
iteration's own speed is in ``curves.csv``). Exit codes: 0 done, 1 a run failed (the finished
runs are written, marked incomplete), 2 bad input (nothing is run), 130 Ctrl-C (as for 1).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path
from typing import Sequence

from agents.common.provenance import provenance
from agents.curves.outputs import CURVE_METRICS, CurvesResult, final_rows, summary_rows, write_outputs
from agents.curves.runs import SeedTask, baseline_seeds, resumable, train_seed
from agents.execution import INTERRUPTED, BackendError, add_backend_arguments, backend_from_args
from marl_vertiport.config import ConfigError, build_dataclass, to_dict


PROG = "python -m agents.curves"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configs", nargs="+", default=["scratch"], metavar="CONFIG",
                        help="train configs: names in configs/train/ or YAML paths (default: scratch)")
    parser.add_argument("--seeds", type=int, default=3, metavar="N", help="training seeds per config (default 3)")
    parser.add_argument("--first-seed", type=int, default=0, metavar="S",
                        help="the first training seed (default 0)")
    parser.add_argument("--iterations", type=int, default=None, metavar="N",
                        help="override every config's PPO iterations")
    parser.add_argument("--baselines", nargs="*", default=["fcfs", "dispatcher"], metavar="AGENT",
                        help="controllers drawn as horizontal lines (default: fcfs dispatcher)")
    parser.add_argument("--baseline-episodes", type=int, default=20, metavar="N",
                        help="validation days per baseline and scenario (default 20; 0: none)")
    parser.add_argument("--workers", type=int, default=2, metavar="N",
                        help="local worker processes, or the CPUs of a Ray instance of its own "
                             "(default 2)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="output folder (default: runs/curves/<configs>)")
    parser.add_argument("--resume", action="store_true",
                        help="go on with the runs already in --out from their last checkpoint "
                             "(the same config; --iterations may extend them)")
    add_backend_arguments(parser)
    return parser


def load_configs(names: Sequence[str], iterations: int | None) -> dict[str, dict]:
    """Each train config by its label (the file's stem), resolved and validated."""
    from agents.training.config import TrainConfig, load_train_config

    configs = {}
    for name in names:
        label = Path(name).stem
        if label in configs:
            raise ConfigError(f"train config {name!r} is given twice")
        cfg = to_dict(load_train_config(name))
        if iterations is not None:  # checked as the config's own key
            cfg["iterations"] = iterations
            build_dataclass(TrainConfig, cfg)
        configs[label] = cfg
    return configs


def scenarios_of(cfg: dict) -> tuple[str, ...]:
    return tuple(cfg["scenarios"]) or (cfg["env_config"],)


def run_baselines(result: CurvesResult, agents: Sequence[str], episodes: int, backend) -> None:
    """Each baseline's mean and CI per metric on ``episodes`` validation days of every
    scenario set of the configs (the mean over its scenarios, weighted equally, as the
    training copies cycle through them)."""
    from agents.evaluate.run import evaluate
    from agents.evaluate.settings import EvalSettings
    from agents.evaluate.stats import bootstrap_ci

    first, stop = baseline_seeds(episodes)
    result.baseline_seeds = (first, stop)
    sets = list(dict.fromkeys(scenarios_of(result.configs[label]) for label in result.labels))
    scenarios = list(dict.fromkeys(s for group in sets for s in group))
    print(f"baselines {', '.join(agents)}: {episodes} validation days ({first}:{stop}) on "
          f"{', '.join(scenarios)}", flush=True)
    evaluation = evaluate(EvalSettings(agents=tuple(agents), configs=tuple(scenarios),
                                       episodes=episodes, first_seed=first),
                          backend=backend, progress=False)
    if evaluation.error:
        raise RuntimeError(f"baselines: {evaluation.error}")
    for group in sets:
        for agent in agents:
            for metric, _ in CURVE_METRICS:
                days = [[float(r.metrics[metric]) for r in evaluation.records
                         if r.task.agent == agent and r.task.config == s] for s in group]
                # Day k of the set: the mean over its scenarios of day k.
                per_day = [sum(v) / len(v) for v in zip(*days)]
                low, high = bootstrap_ci(per_day)
                result.baselines.append({"agent": agent, "scenarios": " + ".join(group),
                                         "metric": metric, "mean": sum(per_day) / len(per_day),
                                         "ci_low": low, "ci_high": high, "days": len(per_day)})


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    args = build_parser(prog).parse_args(argv)
    command = shlex.join([*prog.split(), *(argv if argv is not None else sys.argv[1:])])
    backend = None
    try:
        if args.seeds < 1:
            raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
        if args.baseline_episodes < 0:
            raise ConfigError(f"--baseline-episodes must be >= 0, got {args.baseline_episodes}")
        configs = load_configs(args.configs, args.iterations)
        labels = list(configs)
        out = args.out or Path("runs/curves") / "_".join(labels)
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out {out}: a file is in the way of the output folder")
        seeds = list(range(args.first_seed, args.first_seed + args.seeds))
        from agents.evaluate.run import check_agent

        for agent in args.baselines:
            check_agent(agent)
        tasks = []
        for label in labels:
            for seed in seeds:
                run_dir = out / "runs" / f"{label}_seed{seed}"
                config = {**configs[label], "seed": seed}
                resume = args.resume and resumable(run_dir, config)
                tasks.append(SeedTask(label, config, str(run_dir), resume))
        backend = backend_from_args(args, args.workers)
    except (ConfigError, BackendError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    result = CurvesResult(labels=labels, configs=configs, seeds=seeds, backend=backend.describe(),
                          provenance=provenance(args.baselines if args.baseline_episodes else ()))
    for task in tasks:
        result.run_dirs[(task.label, task.seed)] = task.run_dir
    start = time.perf_counter()

    def on_result(i: int, run: dict) -> bool:
        task = tasks[i]
        result.runs[(task.label, task.seed)] = run
        result.seconds = time.perf_counter() - start
        write_outputs(result, out, command)  # the finished runs so far, marked incomplete
        print(f"done: {task.label} seed {task.seed} in {run['seconds'] / 60:.1f} min "
              f"({len(result.runs)}/{len(tasks)} runs)", flush=True)
        return True

    try:
        print(f"{len(tasks)} training runs ({', '.join(labels)} x seeds {seeds[0]}..{seeds[-1]}) on "
              f"{backend.describe()}; each run's folder: {out}/runs/", flush=True)
        for task in tasks:
            if task.resume:
                print(f"resuming {task.label} seed {task.seed} from {task.run_dir}", flush=True)
        result.error = backend.run(train_seed, tasks, on_result)
        if result.error is None and args.baselines and args.baseline_episodes:
            run_baselines(result, args.baselines, args.baseline_episodes, backend)
    except KeyboardInterrupt:
        result.error = INTERRUPTED
    except RuntimeError as exc:
        result.error = str(exc)
    finally:
        backend.close()
    result.seconds = time.perf_counter() - start
    summary = summary_rows(result)
    files = write_outputs(result, out, command, summary)
    for row in final_rows(summary):
        print(f"{row['config']:>24s} {row['metric']:>14s} at {row['env_steps']:>9,d} steps: "
              f"mean {row['mean']:9.2f} [{row['ci_low']:.2f}, {row['ci_high']:.2f}], "
              f"IQM {row['iqm']:9.2f} [{row['iqm_low']:.2f}, {row['iqm_high']:.2f}], "
              f"{row['seeds']} seeds")
    for base in result.baselines:
        if base["metric"] == "total_reward":
            print(f"{'baseline ' + base['agent']:>24s} total_reward on {base['scenarios']}: "
                  f"{base['mean']:.1f} [{base['ci_low']:.1f}, {base['ci_high']:.1f}]")
    print("wrote " + ", ".join(str(f) for f in files))
    if result.error:
        print(f"error: {result.error}; the finished runs are written, marked incomplete",
              file=sys.stderr)
        return 130 if result.error == INTERRUPTED else 1
    return 0
