"""``python -m agents.train`` / ``marl-vertiport train`` (``make train``): train the GCN ATC.

A run goes into its own folder (``--run-dir``, default ``runs/train/<config>_<time>``);
``--resume <run folder>`` continues an interrupted one, and with ``--rounds N`` takes its warm
start on to N DAgger rounds (PPO then starts again from the new warm start). ``--workers`` and ``--backend`` say
where the warm start's and the ensemble's days run; the checkpoints do not depend on them
(docs/training.md, "Reproducibility"). The stages are in :mod:`agents.training.pipeline`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import yaml

from agents.common.files import write_atomic
from agents.execution import BackendError, add_backend_arguments, backend_from_args
from agents.training.callbacks import TrainingDiverged
from agents.training.checkpoints import WARM_STATE
from agents.training.config import TrainConfig, load_train_config
from agents.training.pipeline import train
from marl_vertiport.config import ConfigError, build_dataclass, to_dict


def main(argv: list[str] | None = None, prog: str = "python -m agents.train") -> int:
    """Command line entry point; returns the exit code (0 done, 2 bad input, 3 diverged)."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="default", help="name in configs/train/ or a YAML path")
    parser.add_argument("--resume", metavar="RUN_DIR", help="continue the run in this folder")
    parser.add_argument("--run-dir", help="folder of a new run (default runs/train/<config>_<time>)")
    parser.add_argument("--rounds", type=int, metavar="N",
                        help="with --resume: take the run's warm start on to N DAgger rounds "
                             "(more than it has; pretrain.dagger_rounds in its train_config.yaml "
                             "becomes N); PPO's outputs from the old warm start are moved to "
                             "<run>/after_<k>_rounds/ and PPO starts again from the new one")
    parser.add_argument("--seed", type=int, help="override the config's seed")
    parser.add_argument("--iterations", type=int, help="override the number of PPO iterations")
    parser.add_argument("--device", help="override the device (cpu, cuda, cuda:0)")
    parser.add_argument("--no-eval", action="store_true", help="skip the evaluation at the end")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="processes for the warm start's and the ensemble's days (1: this "
                             "process; with --backend ray, the CPUs of a Ray instance of its "
                             "own); default: the config's pretrain.workers. The checkpoints do "
                             "not depend on it")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    backend = None
    try:
        if args.resume:
            run_dir = Path(args.resume)
            if not (run_dir / "train_config.yaml").is_file():
                raise ConfigError(f"{run_dir}: not a training run (no train_config.yaml)")
            cfg = load_train_config(run_dir / "train_config.yaml")
        else:
            cfg = load_train_config(args.config)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            seed = "" if args.seed is None else f"_seed{args.seed}"
            run_dir = Path(args.run_dir or f"runs/train/{Path(args.config).stem}{seed}_{stamp}")
        overrides = {}
        if args.seed is not None:
            if args.resume:
                raise ConfigError("--seed: a resumed run keeps the seed it was started with")
            overrides["seed"] = args.seed
        if args.rounds is not None:
            if not args.resume:
                raise ConfigError("--rounds: only with --resume (a new run takes "
                                  "pretrain.dagger_rounds from its config)")
            if args.rounds <= cfg.pretrain.dagger_rounds or not cfg.pretrain.runs:
                raise ConfigError(f"--rounds {args.rounds}: the run's warm start has "
                                  f"{cfg.pretrain.dagger_rounds} DAgger rounds"
                                  + ("" if cfg.pretrain.runs else " and no demonstration days")
                                  + "; it can only go on to more")
            if not (run_dir / WARM_STATE).is_file():
                raise ConfigError(f"--rounds: {run_dir} has no warm-start progress "
                                  f"({WARM_STATE}) to go on from")
            overrides["pretrain"] = {**to_dict(cfg.pretrain), "dagger_rounds": args.rounds}
        if args.iterations is not None:
            overrides["iterations"] = args.iterations
        if args.device is not None:
            overrides["device"] = args.device
        if overrides:
            cfg = build_dataclass(TrainConfig, {**to_dict(cfg), **overrides})
        if args.workers is not None and args.workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {args.workers}")
        backend = backend_from_args(args, args.workers or cfg.pretrain.workers)
        backend_args = ["--backend", args.backend] + (
            ["--ray-address", args.ray_address] if args.ray_address else [])
        if args.rounds is not None:  # the run's config says what it now is
            write_atomic(run_dir / "train_config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
        final = train(cfg, run_dir, resume=bool(args.resume), evaluate=not args.no_eval,
                      backend=backend, backend_args=backend_args)
    except (ConfigError, FileNotFoundError, FileExistsError, ValueError, TrainingDiverged,
            BackendError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2 if not isinstance(exc, TrainingDiverged) else 3
    finally:
        if backend is not None:
            backend.close()
    print(f"done: {final}")
    return 0
