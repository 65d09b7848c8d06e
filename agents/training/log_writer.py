"""Training progress through rsl_rl's supported extension point, a :class:`LogWriter`.

rsl_rl's logger hands every scalar of an iteration to its writer: ``Episode/<metric>``, the
losses (``Loss/<name>``, ``Loss/learning_rate``), ``Policy/mean_std``, ``Perf/total_fps``,
``Perf/collection_time``, ``Perf/learning_time`` and, once episodes have ended,
``Train/mean_reward`` and ``Train/mean_episode_length``. :class:`RunLogWriter` writes them to
TensorBoard, as rsl_rl's default writer does, and passes each iteration's scalars to the
:class:`IterationListener` that the training pipeline registered for the run folder:

* ``iteration_updated(it, scalars)`` once ``Perf/learning_time`` arrives, the last scalar every
  iteration logs, and before the next iteration starts (checks that must stop or change
  training, such as a divergence check, go here);
* ``iteration_done(it, scalars)`` when all of the iteration's scalars are in: at the next
  iteration's first scalar, or when the writer stops.

The writer is built by rsl_rl from ``train_cfg["logger"] = {"class_name":
"agents.training.log_writer:RunLogWriter"}``; it finds its listener by the run folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from rsl_rl.utils.log_writer import LogWriter

#: The scalar every iteration logs last but for the ``Train/`` ones.
LAST_EVERY_ITERATION = "Perf/learning_time"

_LISTENERS: dict[str, IterationListener] = {}


class IterationListener(Protocol):
    def iteration_updated(self, it: int, scalars: dict[str, float]) -> None: ...

    def iteration_done(self, it: int, scalars: dict[str, float]) -> None: ...


def _key(log_dir: str | Path) -> str:
    return str(Path(log_dir).resolve())


def register_listener(log_dir: str | Path, listener: IterationListener) -> None:
    """Send the scalars of the run in ``log_dir`` to ``listener``."""
    _LISTENERS[_key(log_dir)] = listener


def unregister_listener(log_dir: str | Path) -> None:
    _LISTENERS.pop(_key(log_dir), None)


class RunLogWriter(LogWriter):
    """TensorBoard plus the run's listener (see the module docstring).

    Args:
        log_dir: the run folder (given by rsl_rl).
        tensorboard: also write TensorBoard event files there.
    """

    def __init__(self, log_dir: str, tensorboard: bool = True) -> None:
        self.tensorboard = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter

            self.tensorboard = SummaryWriter(log_dir=log_dir, flush_secs=10)
        self.listener = _LISTENERS.get(_key(log_dir))
        self.it: int | None = None
        self.scalars: dict[str, float] = {}

    def add_scalar(self, tag: str, scalar_value: float, global_step: int) -> None:
        if self.tensorboard is not None:
            self.tensorboard.add_scalar(tag, scalar_value, global_step)
        if self.listener is None or tag.endswith("/time"):  # those are indexed by seconds
            return
        if self.it is not None and global_step != self.it:
            self._finish()
        self.it = global_step
        self.scalars[tag] = float(scalar_value)
        if tag == LAST_EVERY_ITERATION:
            self.listener.iteration_updated(global_step, dict(self.scalars))

    def _finish(self) -> None:
        if self.it is not None and self.listener is not None:
            self.listener.iteration_done(self.it, dict(self.scalars))
        self.it, self.scalars = None, {}

    def stop(self) -> None:
        self._finish()
        if self.tensorboard is not None:
            self.tensorboard.close()
