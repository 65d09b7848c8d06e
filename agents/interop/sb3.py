"""The vertiport in Stable-Baselines3: sb3-contrib's ``MaskablePPO`` with ``"MlpPolicy"`` on the
single-agent env with the flat ``Box`` observation (``marl_vertiport/VertiportFlat-v1``,
:mod:`marl_vertiport.flat`). Needs the sb3 extra (``pip install -e '.[sb3]'``).

What SB3 needs from the env, and where it finds it: a ``Box`` observation (SB3 refuses nested
``Dict`` spaces), and the acting eVTOL's legal actions through ``env.action_masks()``, which
``MaskablePPO`` calls before every action (an illegal action would raise ``ValueError``). The
recipe, as a script::

    python -m agents.interop.sb3 --config paper --steps 20000 --out runs/sb3/paper.zip

or in Python::

    from agents.interop.sb3 import make_env, train
    model = train("paper", steps=20000, seed=0)
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from agents.interop import require

__all__ = ["EXTRA", "make_env", "train"]

EXTRA = "sb3"
require("sb3_contrib", EXTRA)  # fail at import, with the install command, without the extra


def make_env(config: Any = "paper", **overrides: Any):
    """``gymnasium.make("marl_vertiport/VertiportFlat-v1", config=config, **overrides)``."""
    import gymnasium

    import marl_vertiport  # noqa: F401  (registers the ids)

    return gymnasium.make("marl_vertiport/VertiportFlat-v1", config=config, **overrides)


def train(config: Any = "paper", *, steps: int = 20_000, seed: int = 0, n_steps: int = 1024,
          batch_size: int = 256, n_epochs: int = 4, verbose: int = 0, **overrides: Any):
    """``MaskablePPO("MlpPolicy")`` on :func:`make_env` for ``steps`` env steps; the model."""
    import torch
    from sb3_contrib import MaskablePPO

    torch.set_num_threads(1)  # faster than two for these small networks
    model = MaskablePPO("MlpPolicy", make_env(config, **overrides), n_steps=n_steps,
                        batch_size=batch_size, n_epochs=n_epochs, seed=seed, device="cpu",
                        verbose=verbose)
    return model.learn(total_timesteps=steps)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.interop.sb3",
                                     description="MaskablePPO (sb3-contrib) on the flat "
                                                 "single-agent vertiport env.")
    parser.add_argument("--config", default="paper", help="env config name or YAML path")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps to train for")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="where to save the model (.zip)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    model = train(args.config, steps=args.steps, seed=args.seed, verbose=1)
    seconds = time.perf_counter() - start
    print(f"{args.steps} steps in {seconds:.0f} s ({args.steps / seconds:.0f} steps/s)")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp.zip")
        model.save(tmp)  # then renamed: never a half-written model under the name asked for
        os.replace(tmp, out)
        print(f"saved {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
