"""A trained GCN checkpoint as a controller (``act(observation) -> action``).

The models are size-agnostic: a checkpoint acts on any vertiport layout and fleet size. It
carries the feature schema it was trained with (the column names of the observation groups);
a checkpoint whose schema differs from this version's, or an observation whose feature columns
do not match it, is refused with both named, and a file that is not a complete training
checkpoint is refused when it is loaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from agents.controllers.base import Controller
from agents.gcn.fast import FastGraphActor
from agents.gcn.features import POLICY_GROUPS
from agents.gcn.padding import to_tensordict
from marl_vertiport.sim.schema import ActionLayout


#: The actor class whose checkpoints the GCN controller plays (``model.actor_class`` of a train
#: config; older checkpoints, which do not name one, were made with it).
GRAPH_ACTOR = "agents.gcn.models:GraphActor"


class CheckpointError(ValueError):
    """A file that is not a usable marl_vertiport checkpoint, or one that does not fit the env."""


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path}: no such file")
    try:
        # Tensors and plain data only: code pickled into the file is refused, never run.
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated or foreign file: torch raises many kinds
        raise CheckpointError(f"checkpoint {path} is corrupt or not a torch file "
                              f"({type(exc).__name__}: {_first_line(exc)})") from None
    meta = (data.get("infos") or {}).get("marl_vertiport") if isinstance(data, dict) else None
    if meta is None or "actor_state_dict" not in data:
        raise CheckpointError(f"checkpoint {path} is not a marl_vertiport training checkpoint "
                              "(no actor weights or run metadata)")
    return data


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def check_weights(path: Path | str, state_dict: dict[str, Any]) -> None:
    """Refuse weights that are not all finite tensors, naming the first bad one."""
    for name, value in state_dict.items():
        if not isinstance(value, torch.Tensor):
            raise CheckpointError(f"checkpoint {path}: weight {name!r} is not a tensor")
        if value.is_floating_point() and not torch.isfinite(value).all():
            raise CheckpointError(f"checkpoint {path}: weight {name!r} has NaN or infinite "
                                  "values (a diverged run?)")


class GCNController(Controller):
    """Greedy (or sampling) action of a trained shared GCN actor.

    Args:
        path: a ``model_<it>.pt`` written by ``python -m agents.train``, or the content of one
            (a dict with ``actor_state_dict`` and ``infos``).
        deterministic: take the most likely legal action (default) instead of sampling.
    """

    def __init__(self, path: str | Path | dict[str, Any], deterministic: bool = True,
                 seed: int | None = None) -> None:
        from agents.gcn.features import feature_names
        from agents.gcn.models import GraphActor
        from agents.gcn.padding import example_observation

        # One intra-op thread: a single-observation forward pass is mostly overhead, and
        # evaluation runs one process per core.
        torch.set_num_threads(1)
        if isinstance(path, dict):  # checkpoint content already in memory (a learner in training)
            data, self.path = path, Path("<in memory>")
        else:
            self.path = Path(path)
            data = read_checkpoint(self.path)
        self.name = f"gcn:{self.path.name}"
        meta = data["infos"]["marl_vertiport"]
        schema = feature_names("observation")
        if meta.get("feature_schema") != schema:
            raise CheckpointError(
                f"checkpoint {self.path} was trained on observation features "
                f"{meta.get('feature_schema', '(not recorded: a fixed-size model of format 1)')}, "
                f"this version observes {schema}; retrain it (make train)")
        model = meta["train_config"]["model"]
        actor_class = model.get("actor_class", GRAPH_ACTOR)
        if actor_class != GRAPH_ACTOR:
            # The class is not imported: a file must never name code that loading it runs.
            raise CheckpointError(f"checkpoint {self.path} was trained with the actor class "
                                  f"{actor_class}; this controller plays {GRAPH_ACTOR} checkpoints")
        example = example_observation()
        self.feature_counts = {"port_nodes": len(schema["ports"]), "evtol_nodes": len(schema["evtols"]),
                               "self": len(schema["extra"])}
        groups = {"actor": list(POLICY_GROUPS)}
        self.actor = GraphActor(example, groups, "actor", 1, feature_names("observation"),
                                hidden=model["hidden"], hidden_dims=model["hidden_dims"])
        check_weights(self.path, data["actor_state_dict"])
        try:
            self.actor.load_state_dict(data["actor_state_dict"])
        except RuntimeError as exc:  # torch lists every mismatch over many lines; the first says it
            raise CheckpointError(f"checkpoint {self.path}: its weights do not fit the GCN actor "
                                  f"({_first_line(exc)})") from None
        self.actor.eval()
        self.deterministic = deterministic
        self.generator = torch.Generator().manual_seed(seed or 0)
        self.train_info = meta
        # A greedy controller scores one observation at a time: the NumPy forward pass gives
        # the torch actor's logits at a tenth of its overhead (agents/gcn/fast.py).
        self._fast = FastGraphActor(self.actor) if deterministic else None

    @staticmethod
    def _tensors(observation: dict) -> TensorDict:
        """One AEC observation as a batch of one (:func:`agents.gcn.padding.to_tensordict`)."""
        inner = observation["observation"]
        arrays = {k: np.asarray(inner[k])[None] for k in POLICY_GROUPS}
        arrays["action_mask"] = np.asarray(observation["action_mask"])[None]
        return to_tensordict(arrays, 1)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.generator.manual_seed(seed)

    def act(self, observation: dict) -> int:
        if self._fast is not None:
            self.check_columns(observation)
            return self._fast.act(observation)
        obs = self.checked_tensors(observation)
        with torch.no_grad():
            probs = self.actor.action_probabilities(obs)
            return int(torch.multinomial(probs, 1, generator=self.generator).item())

    def action_probabilities(self, observation: dict) -> np.ndarray:
        """The policy's probability of each action ``(A,)`` for one AEC observation, 0 on
        masked ones (the decision log's alternatives; greedy play takes the largest)."""
        if self._fast is not None:
            self.check_columns(observation)
            return masked_softmax(self._fast.logits(observation), observation["action_mask"])
        with torch.no_grad():
            return self.actor.action_probabilities(self.checked_tensors(observation))[0].numpy()

    def fast(self) -> Controller:
        """This checkpoint's greedy actions as a stateless controller (``pure_act``), for
        look-aheads that call the policy at every simulated turn. A sampling controller
        (``deterministic=False``) has none."""
        if self._fast is None:
            raise ValueError(f"{self.name}: a sampling GCN controller has no greedy copy")
        return FastGCNController(self)

    def check_columns(self, observation: dict) -> None:
        """Refuse (``CheckpointError``) an AEC observation whose feature columns or action mask
        are not those this checkpoint reads."""
        inner = observation["observation"]
        for key, count in self.feature_counts.items():
            width = np.shape(inner[key])[-1]
            if width != count:
                raise CheckpointError(
                    f"checkpoint {self.path} reads {key} with {count} feature columns, but the "
                    f"observation has {width}: another observation schema")
        n_nodes = np.shape(inner["port_nodes"])[0]
        width = np.shape(observation["action_mask"])[-1]
        if width != ActionLayout(n_nodes).n:
            raise CheckpointError(f"action mask of width {width} for {n_nodes} vertiport nodes: "
                                  f"expected {ActionLayout(n_nodes).n}")

    def checked_tensors(self, observation: dict) -> TensorDict:
        """One AEC observation as the actor's batch of one, after :meth:`check_columns`."""
        self.check_columns(observation)
        return self._tensors(observation)


class FastGCNController(Controller):
    """The greedy actions of a :class:`GCNController` without its checks of the observation's
    columns, a pure function of the observation (:meth:`GCNController.fast`): the policy of a
    look-ahead's rollouts, whose observations the simulator builds."""

    pure_act = True

    def __init__(self, source: GCNController) -> None:
        self.name = f"{source.name}:fast"
        self.actor = source._fast

    def act(self, observation: dict) -> int:
        return self.actor.act(observation)


def masked_softmax(scores: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(A,)`` float64 probabilities of one observation's actions from their ``scores``
    (logits or log-probabilities), 0 where ``mask`` is 0."""
    legal = np.asarray(mask).astype(bool)
    z = np.where(legal, np.asarray(scores, dtype=np.float64), -np.inf)
    e = np.exp(z - z[legal].max())
    return e / e.sum()


def mean_log_probabilities(actors: list, obs: TensorDict) -> torch.Tensor:
    """``(B, A)`` the members' masked log-probabilities on a batch, averaged over ``actors``
    (an ensemble's policy, up to normalisation); very negative on illegal actions."""
    from agents.gcn.distribution import masked_logits

    with torch.no_grad():
        return torch.stack([torch.log_softmax(masked_logits(a.logits(obs), obs["action_mask"]),
                                              dim=-1) for a in actors]).mean(0)


class GCNEnsemble(Controller):
    """Several trained GCN actors as one controller: the legal action with the largest mean
    log-probability over the members (their geometric-mean policy), greedily.

    Fits of the same demonstrations with different seeds play quite differently
    (``python -m agents.studies.refit``); their ensemble averages that luck out. In an agent
    spec, checkpoints joined by ``+`` name an ensemble: ``run/model_warmstart.pt+refit/model_refit1.pt``.

    Args:
        paths: two or more checkpoints (paths, or checkpoint contents), each checked as by
            :class:`GCNController`.
    """

    pure_act = True

    def __init__(self, paths: list[str | Path | dict[str, Any]]) -> None:
        if len(paths) < 2:
            raise CheckpointError(f"an ensemble needs two or more checkpoints, got {len(paths)}")
        self.members = [GCNController(p) for p in paths]
        self.name = "gcn-ensemble:" + "+".join(m.path.name for m in self.members)

    def action_probabilities(self, observation: dict) -> np.ndarray:
        """The ensemble's policy ``(A,)``: the members' mean log-probabilities, normalised
        over the legal actions (0 on masked ones)."""
        obs = self.members[0].checked_tensors(observation)
        logp = mean_log_probabilities([m.actor for m in self.members], obs)[0].numpy()
        return masked_softmax(logp, observation["action_mask"])

    def act(self, observation: dict) -> int:
        # Every member reads this version's feature schema (GCNController refuses others), so
        # one checked batch serves them all.
        obs = self.members[0].checked_tensors(observation)
        logp = mean_log_probabilities([m.actor for m in self.members], obs)[0]
        mask = torch.as_tensor(np.asarray(observation["action_mask"]), dtype=torch.bool)
        return int(torch.where(mask, logp, -torch.inf).argmax().item())
