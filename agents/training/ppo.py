"""rsl_rl's PPO with a critic warm-up and a linear learning-rate schedule, plugged in through
``algorithm.class_name``.

For the first ``critic_warmup_updates`` updates the actor's parameters take no gradient, so the
critic fits the values of a warm-started actor before the actor's advantages move it. With
``schedule="linear"`` the learning rate before update ``u`` of ``total_updates`` is
``learning_rate * (1 - u / total_updates)``. Both counts carry over a resumed run (the pipeline
sets :attr:`WarmupPPO.updates_done` from the loaded iteration).

Each update also reports the actor's gradient norm before rsl_rl clips it to
``max_grad_norm`` (the mean over the update's gradient steps, ``actor_grad_norm``) and the
share of those steps whose actor gradient the clip scaled down (``actor_clip_fraction``); both
0 while the actor is frozen. They reach ``curves.csv`` as columns of those names.
"""

from __future__ import annotations

import torch
from rsl_rl.algorithms import PPO


class GradNormProbe:
    """The norm of a module's gradient at each optimiser step, before any clipping.

    Each parameter's post-accumulate-grad hook adds its squared gradient norm when the
    backward pass has finished it; the optimiser's step pre-hook, which runs after rsl_rl's
    clip, closes the step. Steps in which no parameter of the module took a gradient (the
    actor frozen) are not counted. Gradients taken outside the watched optimiser's steps (an
    imitation fit of the same module) are dropped by :meth:`reset`.

    Args:
        module: whose parameters are watched.
        optimizer: the optimiser that steps them.
    """

    def __init__(self, module: torch.nn.Module, optimizer: torch.optim.Optimizer) -> None:
        self._square: torch.Tensor | None = None
        self._norms: list[torch.Tensor] = []
        for param in module.parameters():
            param.register_post_accumulate_grad_hook(self._add)
        optimizer.register_step_pre_hook(self._close)

    def _add(self, param: torch.Tensor) -> None:
        square = param.grad.detach().pow(2).sum()
        self._square = square if self._square is None else self._square + square

    def _close(self, *_) -> None:
        if self._square is not None:
            self._norms.append(self._square.sqrt())
        self._square = None

    def reset(self) -> None:
        """Forget every gradient seen so far."""
        self._square = None
        self._norms.clear()

    def pop(self) -> list[float]:
        """The norms of the steps since the last call, oldest first."""
        norms = [float(n) for n in self._norms]
        self._norms.clear()
        return norms


class WarmupPPO(PPO):
    """:class:`rsl_rl.algorithms.PPO` whose actor is frozen for the first updates.

    Args:
        critic_warmup_updates: updates with the actor frozen (0: plain PPO).
        total_updates: the run's updates, for ``schedule="linear"``.
        *args, **kwargs: those of :class:`~rsl_rl.algorithms.PPO` (``schedule`` may also be
            ``"linear"``).
    """

    def __init__(self, *args, critic_warmup_updates: int = 0, total_updates: int = 1,
                 **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.critic_warmup_updates = critic_warmup_updates
        self.total_updates = max(int(total_updates), 1)
        self.initial_learning_rate = self.learning_rate
        #: Updates done so far in this run (across resumes).
        self.updates_done = 0
        self.actor_grad_probe = GradNormProbe(self.actor, self.optimizer)

    @property
    def actor_frozen(self) -> bool:
        return self.updates_done < self.critic_warmup_updates

    def update(self) -> dict[str, float]:
        if self.schedule == "linear":
            left = max(1.0 - self.updates_done / self.total_updates, 0.0)
            self.learning_rate = self.initial_learning_rate * left
            for group in self.optimizer.param_groups:
                group["lr"] = self.learning_rate
        frozen = self.actor_frozen
        if frozen:
            self.actor.requires_grad_(False)
        probe = getattr(self, "actor_grad_probe", None)  # absent where built without __init__
        if probe is not None:
            probe.reset()
        try:
            losses = super().update()
            if probe is not None:
                norms = probe.pop()
                losses["actor_grad_norm"] = sum(norms) / len(norms) if norms else 0.0
                losses["actor_clip_fraction"] = (
                    sum(n > self.max_grad_norm for n in norms) / len(norms) if norms else 0.0)
            return losses
        finally:
            self.updates_done += 1
            if frozen and not self.actor_frozen:
                self.actor.requires_grad_(True)
