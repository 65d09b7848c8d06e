"""The small torch pieces both adapters' policies are built from (torch only, no RL library)."""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["mlp", "symlog"]


def symlog(x: torch.Tensor) -> torch.Tensor:
    """sign(x) log(1 + |x|): metres, minutes and percents on one scale without statistics."""
    return torch.sign(x) * torch.log1p(x.abs())


def mlp(n_in: int, n_out: int, hidden: int) -> nn.Sequential:
    """``(..., n_in) -> (..., n_out)``: two tanh layers of ``hidden`` units."""
    return nn.Sequential(nn.Linear(n_in, hidden), nn.Tanh(), nn.Linear(hidden, hidden),
                         nn.Tanh(), nn.Linear(hidden, n_out))
