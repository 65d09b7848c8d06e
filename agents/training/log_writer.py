"""Training progress through rsl_rl's supported extension point, a :class:`LogWriter`.

rsl_rl's logger hands every scalar of an iteration to its writer: ``Episode/<metric>``, the
losses (``Loss/<name>``, ``Loss/learning_rate``), ``Policy/mean_std``, ``Perf/total_fps``,
``Perf/collection_time``, ``Perf/learning_time`` and, once episodes have ended,
``Train/mean_reward`` and ``Train/mean_episode_length``. :class:`RunLogWriter` writes them to
TensorBoard, as rsl_rl's default writer does, and passes each iteration's scalars to the run's
:class:`~agents.training.callbacks.Callback`:

* ``on_iteration(it, scalars)`` once ``Perf/learning_time`` arrives, the last scalar every
  iteration logs, and before the next iteration starts;
* ``on_iteration_end(it, scalars)`` when all of the iteration's scalars are in: at the next
  iteration's first scalar, or when the writer stops.

rsl_rl builds the writer from ``train_cfg["logger"] = {"class_name":
"agents.training.log_writer:RunLogWriter"}``; the callback object travels in the runner's
config as ``train_cfg["callback"]`` and reaches the writer through rsl_rl's
``LogWriter.store_config``, which the logger calls once, before the first iteration.
"""

from __future__ import annotations

from typing import Any

from rsl_rl.utils.log_writer import LogWriter

#: The scalar every iteration logs last but for the ``Train/`` ones.
LAST_EVERY_ITERATION = "Perf/learning_time"
#: The key of the runner's config that holds the run's callback.
CALLBACK_KEY = "callback"


class RunLogWriter(LogWriter):
    """TensorBoard plus the run's callback (see the module docstring).

    Args:
        log_dir: the run folder (given by rsl_rl).
        tensorboard: also write TensorBoard event files there.
    """

    def __init__(self, log_dir: str, tensorboard: bool = True) -> None:
        self.tensorboard = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter

            self.tensorboard = SummaryWriter(log_dir=log_dir, flush_secs=10)
        self.callback: Any = None
        self.it: int | None = None
        self.scalars: dict[str, float] = {}

    def store_config(self, env_cfg: dict | object, train_cfg: dict) -> None:
        self.callback = train_cfg.get(CALLBACK_KEY)

    def add_scalar(self, tag: str, scalar_value: float, global_step: int) -> None:
        if self.tensorboard is not None:
            self.tensorboard.add_scalar(tag, scalar_value, global_step)
        if self.callback is None or tag.endswith("/time"):  # those are indexed by seconds
            return
        if self.it is not None and global_step != self.it:
            self._finish()
        self.it = global_step
        self.scalars[tag] = float(scalar_value)
        if tag == LAST_EVERY_ITERATION:
            self.callback.on_iteration(global_step, dict(self.scalars))

    def _finish(self) -> None:
        if self.it is not None and self.callback is not None:
            self.callback.on_iteration_end(self.it, dict(self.scalars))
        self.it, self.scalars = None, {}

    def stop(self) -> None:
        self._finish()
        if self.tensorboard is not None:
            self.tensorboard.close()
