"""How much of a warm start is the luck of its fit: the same demonstrations, refit from fresh
weights with other seeds.

A training run keeps every decision its warm start was fit on (``warmstart_state.pt``). This
study fits that data again, once per seed, exactly as the run did (its ``pretrain`` epochs,
batch size, learning rate and regret weights) but from weights drawn afresh with seed
``1000 + k`` (``agents.training.ensemble.refit_actor``, which the pipeline's ensemble stage uses),
and writes each actor as a checkpoint that the evaluation loads like the run's own
``model_warmstart.pt``. The spread of their scores on the same days is what the fit alone
contributes; a later training stage has to beat it to be told apart from a lucky fit
(experiments/ensemble-warm-start-rules-v0, "Does the PPO stage improve the warm start?")::

    python -m agents.studies.refit runs/train/default_seed0 --seeds 1 2 3 4 --out runs/refit0
    python -m agents.evaluate --agents runs/train/default_seed0/model_warmstart.pt \\
        runs/refit0/model_refit1.pt ... --configs paper paper_uncertain small twin wide \\
        --episodes 40 --seeds 800010:800050 --out runs/eval_refit0
    python -m agents.evaluate.paired runs/eval_refit0/episodes.csv \\
        --pair runs/train/default_seed0/model_warmstart.pt runs/refit0/model_refit1.pt

Each fit takes under a minute on one core. Files are written atomically; the run's folder is
only read (its files are loaded as tensors and plain data, never as pickled code).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Sequence

import torch

from agents.common.files import write_torch_atomic


def refit(run_dir: str | Path, seeds: Sequence[int], out_dir: str | Path,
          log: Callable[[str], None] = print) -> list[Path]:
    """Fit the warm-start data of ``run_dir`` once per seed from fresh weights; return the
    checkpoints written (``out_dir/model_refit<seed>.pt``).

    Raises:
        ValueError: ``run_dir`` has no warm start to refit, or a file in it cannot be read
            (the message names it).
    """
    from agents.controllers.gcn import GCNController, read_checkpoint
    from agents.training.ensemble import REFIT_SEED_BASE, refit_actor
    from agents.training.imitation import load_warm_start_state
    from agents.training.checkpoints import WARM_STATE
    from agents.training.config import load_train_config

    run_dir, out_dir = Path(run_dir), Path(out_dir)
    for name in ("train_config.yaml", WARM_STATE, "model_warmstart.pt"):
        if not (run_dir / name).is_file():
            raise ValueError(f"{run_dir}: no {name}; refit needs a training run whose warm start "
                             f"finished (pretrain.days > 0)")
    pre = load_train_config(run_dir / "train_config.yaml").pretrain
    data = load_warm_start_state(run_dir / WARM_STATE)["data"]
    if data is None or len(data["label"]) == 0:
        raise ValueError(f"{run_dir / WARM_STATE}: holds no decisions to fit")
    warm = run_dir / "model_warmstart.pt"
    content = read_checkpoint(warm)
    torch.set_num_threads(1)
    written = []
    for seed in seeds:
        # The run's architecture, its weights drawn again (as the pipeline's ensemble stage does).
        actor, stats = refit_actor(GCNController(content).actor, data, pre,
                                   REFIT_SEED_BASE + seed)
        out = {**content, "actor_state_dict": {k: v.detach().clone()
                                               for k, v in actor.state_dict().items()}}
        out["infos"] = {**content["infos"], "refit": {"of": str(warm), "seed": int(seed),
                                                      **{k: float(v) for k, v in stats.items()}}}
        path = out_dir / f"model_refit{seed}.pt"
        write_torch_atomic(path, out)
        written.append(path)
        log(f"refit {seed}: cross-entropy {stats['cross_entropy']:.3f}, teacher-action accuracy "
            f"{stats['accuracy']:.1%} on {int(stats['samples'])} decisions -> {path}")
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.studies.refit", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", help="a training run's folder (with warmstart_state.pt)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4],
                        help="one refit per seed (default 1 2 3 4)")
    parser.add_argument("--out", required=True, help="folder for model_refit<seed>.pt")
    args = parser.parse_args(argv)
    if len(set(args.seeds)) != len(args.seeds) or min(args.seeds) < 0:
        print("error: --seeds must be distinct integers >= 0", file=sys.stderr)
        return 2
    try:
        refit(args.run, args.seeds, args.out)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
