"""A masked categorical distribution for rsl-rl-lib (which ships only continuous ones).

Plugged in through an rsl_rl model's ``distribution_cfg``::

    distribution_cfg = {"class_name": "agents.gcn.distribution:MaskedCategorical", "num_choices": 14}

The model passes the legal-action mask with the logits (``update(logits, mask)``); illegal
actions get probability exactly 0, so they are never sampled and do not count in the entropy.
Actions travel through rsl_rl as float tensors of shape ``(B, 1)`` (its rollout storage is
float32); the environment adapter turns them back into integers.
"""

from __future__ import annotations

import torch
from rsl_rl.modules.distribution import Distribution
from torch import nn


def masked_logits(logits: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Logits with illegal actions set to the most negative finite value.

    A finite fill keeps ``log_softmax`` and ``p * log p`` free of NaN (``0 * finite = 0``).
    """
    if mask is None:
        return logits
    return logits.masked_fill(~mask.bool(), torch.finfo(logits.dtype).min)


class MaskedCategorical(Distribution):
    """Categorical over the actions of a row's logits with a legal-action mask.

    Args:
        output_dim: rsl_rl's action dimension; must be 1 (one discrete action per row).
        num_choices: width of the model's MLP head output (``input_dim``, which rsl_rl sizes
            the head by). A model may append more logits to it (the GCN actor appends one per
            vertiport node), so the distribution takes its width from the logits it is given.
    """

    def __init__(self, output_dim: int, num_choices: int) -> None:
        super().__init__(output_dim)
        if output_dim != 1:
            raise ValueError(f"MaskedCategorical draws one action per row: output_dim must be 1, "
                             f"got {output_dim}")
        self.num_choices = int(num_choices)
        self._logits: torch.Tensor | None = None
        self._log_probs: torch.Tensor | None = None

    # ------------------------------------------------------------------ state
    def update(self, mlp_output: torch.Tensor, mask: torch.Tensor | None = None) -> None:
        """Set the distribution from logits ``(B, A)`` and a mask ``(B, A)``."""
        self._logits = masked_logits(mlp_output, mask)
        self._log_probs = torch.log_softmax(self._logits, dim=-1)

    def sample(self) -> torch.Tensor:
        """Sampled actions, shape ``(B, 1)``, float."""
        return torch.multinomial(self.probs, 1).to(self._logits.dtype)

    def deterministic_output(self, mlp_output: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Most likely legal action, shape ``(B, 1)``, float."""
        return masked_logits(mlp_output, mask).argmax(dim=-1, keepdim=True).to(mlp_output.dtype)

    def as_deterministic_output_module(self) -> nn.Module:
        return _ArgMax()

    # ------------------------------------------------------------------ properties
    @property
    def input_dim(self) -> int:
        return self.num_choices

    @property
    def probs(self) -> torch.Tensor:
        """``(B, A)``; exactly 0 on illegal actions."""
        return self._log_probs.exp()

    @property
    def mean(self) -> torch.Tensor:
        """Expected action index, ``(B, 1)`` (logged by rsl_rl only)."""
        idx = torch.arange(self._logits.shape[-1], device=self._logits.device, dtype=self._logits.dtype)
        return (self.probs * idx).sum(-1, keepdim=True)

    @property
    def std(self) -> torch.Tensor:
        """Standard deviation of the action index, ``(B, 1)`` (rsl_rl logs its mean)."""
        idx = torch.arange(self._logits.shape[-1], device=self._logits.device, dtype=self._logits.dtype)
        var = (self.probs * (idx - self.mean) ** 2).sum(-1, keepdim=True)
        return var.clamp_min(0).sqrt()

    @property
    def entropy(self) -> torch.Tensor:
        """``(B,)``, over the legal actions."""
        p = self.probs
        return -(p * self._log_probs).sum(-1)

    @property
    def params(self) -> tuple[torch.Tensor, ...]:
        """``(masked logits,)``, what rsl_rl stores to compute the KL divergence later."""
        return (self._logits,)

    def log_prob(self, outputs: torch.Tensor) -> torch.Tensor:
        """Log-probabilities ``(B,)`` of actions given as ``(B, 1)`` (float or int)."""
        idx = outputs.reshape(-1, 1).long()
        return self._log_probs.gather(-1, idx).squeeze(-1)

    def kl_divergence(self, old_params: tuple[torch.Tensor, ...], new_params: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """``KL(old || new)`` per row, ``(B,)``."""
        old = torch.log_softmax(old_params[0], dim=-1)
        new = torch.log_softmax(new_params[0], dim=-1)
        return (old.exp() * (old - new)).sum(-1)


class _ArgMax(nn.Module):
    def forward(self, logits: torch.Tensor) -> torch.Tensor:
        return logits.argmax(dim=-1, keepdim=True).to(logits.dtype)
