"""The vertiport env in other RL libraries: what each needs, in one file per library.

* :mod:`agents.interop.torchrl_env`: the AEC env behind TorchRL's ``PettingZooWrapper``
  (``use_mask=True``), or the Parallel env the way BenchMARL builds its tasks, a masked MLP
  actor, a critic that can read ``state()``, and a reference PPO loop (``ClipPPOLoss``, GAE, a
  ``Collector``). Extra: ``torchrl``.
* :mod:`agents.interop.sb3`: sb3-contrib's ``MaskablePPO`` on the flat single-agent env
  (``marl_vertiport/VertiportFlat-v1``). Extra: ``sb3``.
* :mod:`agents.interop.rllib_env`: the AEC env behind RLlib's ``PettingZooEnv``, with the
  observation flattened to ``{"action_mask", "observations"}`` (and ``"state"`` for a
  centralised critic), an action-masking RLModule and a PPO config. Extra: ``rllib``.
* the flattening itself is :class:`marl_vertiport.flat.FlatAEC` (the env layer, no RL library).

Every library has to respect the same three facts of the env: the legal actions travel as
``observation["action_mask"]`` (int8, 1 = legal), an illegal action raises ``ValueError``
(so a learner must mask, never clip), and the global state for a centralised critic comes
from ``env.state()`` (``env.state_space``), not from the observations. Nothing here imports
an RL library at import time; a missing one fails with the command that installs it
(docs/ecosystem.md has the table of every library and its recipe).
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["require"]


def require(module: str, extra: str) -> ModuleType:
    """Import ``module``, or fail with one line that names the extra to install."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(f"{module} cannot be imported ({err}): install the {extra} extra, "
                          f"pip install -e '.[{extra}]'") from err
