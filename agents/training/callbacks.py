"""What a run does at each PPO iteration, as callback objects (as BenchMARL's ``Callback``).

rsl_rl runs the iterations; its log writer (:mod:`agents.training.log_writer`) hands each
iteration's scalars to the run's :class:`Callback`:

* :meth:`Callback.on_iteration` once the update is done (losses, learning rate, timings), before
  the next iteration starts: checks that must stop training go here;
* :meth:`Callback.on_iteration_end` when every scalar of the iteration is in, the training
  days' ``Train/mean_reward`` included.

:class:`RunProgress` is the pipeline's own: the divergence stop, the progress line and the row
of ``curves.csv`` of every iteration. :class:`Callbacks` calls several in turn.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import torch

from agents.training.curves import write_curves


class TrainingDiverged(RuntimeError):
    """A loss or a parameter became NaN or infinite."""


class Callback:
    """A run's hooks; each does nothing unless overridden."""

    def on_iteration(self, it: int, scalars: dict[str, float]) -> None:
        """Iteration ``it`` updated the models; ``scalars`` are rsl_rl's (``Loss/value``,
        ``Loss/learning_rate``, ``Perf/...``). Raising stops the run."""

    def on_iteration_end(self, it: int, scalars: dict[str, float]) -> None:
        """Every scalar of iteration ``it`` is in (``Train/mean_reward`` too, once days end)."""


class Callbacks(Callback):
    """Several callbacks, called in the order given."""

    def __init__(self, callbacks: Sequence[Callback]) -> None:
        self.callbacks = list(callbacks)

    def on_iteration(self, it: int, scalars: dict[str, float]) -> None:
        for callback in self.callbacks:
            callback.on_iteration(it, scalars)

    def on_iteration_end(self, it: int, scalars: dict[str, float]) -> None:
        for callback in self.callbacks:
            callback.on_iteration_end(it, scalars)


class RunProgress(Callback):
    """The pipeline's callback: stop on a non-finite loss or weight, print one progress line
    per iteration (with the training days' metrics when days ended), and add the iteration's
    row to ``curves.csv``.

    Args:
        runner: the rsl_rl runner (its actor and critic are checked).
        vec_env: the run's vector env (the means of the days that ended, per iteration).
        iterations: the run's last iteration + 1; ``start_it``: the first of this call.
        samples_per_it: env steps per iteration.
        curves: the rows of ``curves.csv`` so far (appended to); ``curves_path``: the file.
        run_dir: for the divergence message (the last good checkpoint is there).
        log: where the progress line goes (stdout's own, even while rsl_rl's is silenced).
    """

    def __init__(self, runner: Any, vec_env: Any, iterations: int, start_it: int,
                 samples_per_it: int, curves: list[dict[str, float]], curves_path: Path,
                 run_dir: Path, log: Callable[[str], None] = print) -> None:
        self.runner, self.vec_env = runner, vec_env
        self.iterations, self.start_it, self.samples_per_it = iterations, start_it, samples_per_it
        self.curves, self.curves_path, self.run_dir = curves, curves_path, run_dir
        self.log = log
        self.terminal = sys.stdout
        self.started = time.time()
        self.pending: dict[int, dict[str, float]] = {}

    def _say(self, msg: str) -> None:
        with contextlib.redirect_stdout(self.terminal):
            self.log(msg)

    def on_iteration(self, it: int, scalars: dict[str, float]) -> None:
        alg = self.runner.alg
        bad = [k for k, v in scalars.items() if k.startswith("Loss/") and not math.isfinite(v)]
        params = list(alg.actor.named_parameters()) + list(alg.critic.named_parameters())
        bad_params = [n for n, p in params if not torch.isfinite(p).all()]
        if bad or bad_params:
            raise TrainingDiverged(f"training diverged at iteration {it}: non-finite "
                                   f"{', '.join(bad + bad_params[:3])}; the last good checkpoint "
                                   f"is kept in {self.run_dir}")
        nan = float("nan")
        elapsed = max(time.time() - self.started, 1e-9)
        row = {"iteration": it, "env_steps": (it + 1) * self.samples_per_it,
               "steps_per_s": self.samples_per_it * (it + 1 - self.start_it) / elapsed,
               "mean_reward": nan,
               "value_loss": scalars.get("Loss/value", nan),
               "surrogate_loss": scalars.get("Loss/surrogate", nan),
               "entropy": scalars.get("Loss/entropy", nan),
               "learning_rate": scalars.get("Loss/learning_rate", nan),
               "actor_grad_norm": scalars.get("Loss/actor_grad_norm", nan),
               "actor_clip_fraction": scalars.get("Loss/actor_clip_fraction", nan)}
        row.update(self.vec_env.pop_episode_means())  # the days that ended in this iteration
        self.pending[it] = row
        eta = elapsed / (it + 1 - self.start_it) * (self.iterations - it - 1)
        msg = (f"it {it + 1:4d}/{self.iterations}  {row['steps_per_s']:6.0f} steps/s  "
               f"lr {row['learning_rate']:.1e}  value loss {row['value_loss']:8.3f}")
        if math.isfinite(row.get("total_reward", nan)):
            msg += (f"  | day: reward {row['total_reward']:7.1f} battery {row['mean_battery_pct']:4.1f}% "
                    f"good TO/LD {row['good_takeoffs']:4.1f}/{row['good_landings']:4.1f} "
                    f"delay {row['mean_delay_min']:6.1f} coll {row['collisions']:4.1f} "
                    f"sep loss {row.get('separation_losses', nan):3.1f} "
                    f"contacts {row.get('contacts', nan):3.1f} "
                    f"lost {row['stranded_air']:3.1f} air/{row['stranded_ground']:3.1f} ground")
        self._say(f"{msg}  eta {eta / 60:4.1f} min")

    def on_iteration_end(self, it: int, scalars: dict[str, float]) -> None:
        row = self.pending.pop(it, None)
        if row is None:
            return
        row["mean_reward"] = scalars.get("Train/mean_reward", float("nan"))
        self.curves.append(row)
        write_curves(self.curves_path, self.curves)
