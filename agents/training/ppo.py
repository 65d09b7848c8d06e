"""rsl_rl's PPO with a critic warm-up and a linear learning-rate schedule, plugged in through
``algorithm.class_name``.

For the first ``critic_warmup_updates`` updates the actor's parameters take no gradient, so the
critic fits the values of a warm-started actor before the actor's advantages move it. With
``schedule="linear"`` the learning rate before update ``u`` of ``total_updates`` is
``learning_rate * (1 - u / total_updates)``. Both counts carry over a resumed run (the pipeline
sets :attr:`WarmupPPO.updates_done` from the loaded iteration).
"""

from __future__ import annotations

from rsl_rl.algorithms import PPO


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
        try:
            return super().update()
        finally:
            self.updates_done += 1
            if frozen and not self.actor_frozen:
                self.actor.requires_grad_(True)
