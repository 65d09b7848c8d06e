"""The vertiport in Stable-Baselines3: sb3-contrib's ``MaskablePPO`` with ``"MlpPolicy"`` on the
single-agent env with the flat ``Box`` observation (``marl_vertiport/VertiportFlat-v1``,
:mod:`marl_vertiport.flat`). Needs the sb3 extra (``pip install -e '.[sb3]'``).

What SB3 needs from the env, and where it finds it: a ``Box`` observation (SB3 refuses nested
``Dict`` spaces), and the acting eVTOL's legal actions through ``env.action_masks()``, which
``MaskablePPO`` calls before every action (an illegal action would raise ``ValueError``).

The recipe, as one script: train, save (the model's zip, with the flat columns it was trained
on, :func:`save`), and evaluate the saved file beside the dispatcher on the same days::

    python -m agents.interop.sb3 --config paper --steps 20000 --out runs/sb3/paper.zip \
        --evaluate 5

or in Python::

    from agents.interop.sb3 import make_env, save, train
    model = train("paper", steps=20000, seed=0)
    save(model, "runs/sb3/paper.zip")

Any command then plays the file: ``marl-vertiport evaluate --agents runs/sb3/paper.zip
dispatcher``, ``render --agent runs/sb3/paper.zip`` (:mod:`agents.controllers.foreign`,
weights only).

Speed: torch runs on one thread here (:func:`train` sets it), several times faster than two
for a network this small; on a busy 2-core machine the default threads are up to 10x slower.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import zipfile
from pathlib import Path
from typing import Any

from agents.interop import require

__all__ = ["EXTRA", "make_env", "progress_bar", "save", "train"]

EXTRA = "sb3"
require("sb3_contrib", EXTRA)  # fail at import, with the install command, without the extra


def make_env(config: Any = "paper", **overrides: Any):
    """``gymnasium.make("marl_vertiport/VertiportFlat-v1", config=config, **overrides)``."""
    import gymnasium

    import marl_vertiport  # noqa: F401  (registers the ids)

    return gymnasium.make("marl_vertiport/VertiportFlat-v1", config=config, **overrides)


def train(config: Any = "paper", *, steps: int = 20_000, seed: int = 0, n_steps: int = 1024,
          batch_size: int = 256, n_epochs: int = 4, verbose: int = 0, progress: bool = False,
          **overrides: Any):
    """``MaskablePPO("MlpPolicy")`` on :func:`make_env` for ``steps`` env steps, with a progress
    bar where ``progress``; the model."""
    import torch
    from sb3_contrib import MaskablePPO

    torch.set_num_threads(1)  # several times faster than two for networks this small
    model = MaskablePPO("MlpPolicy", make_env(config, **overrides), n_steps=n_steps,
                        batch_size=batch_size, n_epochs=n_epochs, seed=seed, device="cpu",
                        verbose=verbose)
    return model.learn(total_timesteps=steps, callback=progress_bar(steps) if progress else None)


def progress_bar(steps: int) -> Any:
    """A tqdm bar of ``steps`` env steps, as an SB3 callback for ``model.learn(steps,
    callback=progress_bar(steps))`` (SB3's own ``progress_bar=True`` needs the ``rich``
    package, which the extra does not install)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Bar(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=steps, unit="step", desc="MaskablePPO", dynamic_ncols=True)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return Bar()


def save(model: Any, path: str | Path) -> Path:
    """Save ``model`` (trained on the vertiport's flat env) to ``path`` (``.zip``), with what
    the project's loader checks (:data:`agents.controllers.foreign.METADATA`: the flat columns
    of the vertiport it was trained on) added to the zip. Written under another name first, then
    renamed: never a half-written model under the name asked for."""
    from agents.controllers.foreign import METADATA, metadata_for

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.zip")
    model.save(tmp)
    with zipfile.ZipFile(tmp, "a") as z:
        z.writestr(METADATA, json.dumps(metadata_for(model.get_env().envs[0], "flat")))
    os.replace(tmp, path)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.interop.sb3",
                                     description="MaskablePPO (sb3-contrib) on the flat "
                                                 "single-agent vertiport env: train, save, and "
                                                 "evaluate beside the dispatcher.")
    parser.add_argument("--config", default="paper", help="env config name or YAML path")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps to train for")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="where to save the model (.zip)")
    parser.add_argument("--evaluate", type=int, default=0, metavar="DAYS",
                        help="then evaluate the saved model beside the dispatcher on the first "
                             "DAYS test days of --config (needs --out); its files go to "
                             "<out without .zip>_eval/")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.evaluate and not args.out:
        parser.error("--evaluate needs --out (the file it evaluates)")
    start = time.perf_counter()
    model = train(args.config, steps=args.steps, seed=args.seed, verbose=0,
                  progress=not args.no_progress)
    seconds = time.perf_counter() - start
    print(f"{args.steps} steps in {seconds:.0f} s ({args.steps / seconds:.0f} steps/s)")
    if args.out:
        print(f"saved {save(model, args.out)}")
    if args.evaluate:
        from agents.evaluate import EvalSettings, evaluate, format_table, write_outputs

        settings = EvalSettings(agents=(args.out, "dispatcher"), configs=(args.config,),
                                episodes=args.evaluate)
        evaluation = evaluate(settings, progress=not args.no_progress)
        out = Path(args.out).with_suffix("")
        out = out.with_name(f"{out.name}_eval")
        write_outputs(evaluation, out, "python -m agents.interop.sb3 " + " ".join(argv or []))
        print(format_table(evaluation))
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
