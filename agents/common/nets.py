"""The small torch pieces the adapters' policies are built from, and the loader that rebuilds
an RLlib checkpoint's policy from its weights (torch only, no RL library)."""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import nn

__all__ = ["mlp", "mlp_from_weights", "symlog"]


def symlog(x: torch.Tensor) -> torch.Tensor:
    """sign(x) log(1 + |x|): metres, minutes and percents on one scale without statistics."""
    return torch.sign(x) * torch.log1p(x.abs())


def mlp(n_in: int, n_out: int, hidden: int) -> nn.Sequential:
    """``(..., n_in) -> (..., n_out)``: two tanh layers of ``hidden`` units."""
    return nn.Sequential(nn.Linear(n_in, hidden), nn.Tanh(), nn.Linear(hidden, hidden),
                         nn.Tanh(), nn.Linear(hidden, n_out))


def mlp_from_weights(weights: Mapping[str, torch.Tensor], prefix: str) -> nn.Sequential:
    """The tanh MLP whose layers are ``weights[f"{prefix}{k}.weight"]`` and ``.bias`` for
    ``k = 0, 2, 4, ...`` (:func:`mlp`'s layout, of any depth and widths), with those weights.

    Raises:
        KeyError: no ``f"{prefix}0.weight"`` in ``weights``.
    """
    layers: list[nn.Module] = []
    k = 0
    while f"{prefix}{k}.weight" in weights or k == 0:
        w = torch.as_tensor(weights[f"{prefix}{k}.weight"])
        if layers:
            layers.append(nn.Tanh())
        layers.append(nn.Linear(int(w.shape[1]), int(w.shape[0])))
        k += 2
    net = nn.Sequential(*layers)
    own = {f"{i}.{kind}": torch.as_tensor(weights[f"{prefix}{i}.{kind}"], dtype=torch.float32)
           for i in range(0, k, 2) for kind in ("weight", "bias")}
    net.load_state_dict(own, strict=True)
    return net.eval()
