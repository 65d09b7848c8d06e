"""Policies trained in other libraries, as controllers: read as weights, never as code.

* **Stable-Baselines3** (``path/to/model.zip``, ``PPO`` or sb3-contrib's ``MaskablePPO`` with an
  ``MlpPolicy`` on the flat env ``marl_vertiport/VertiportFlat-v1``). The zip's ``data`` is read
  as JSON only (its pickled parts are never unpickled), ``policy.pth`` with
  ``torch.load(weights_only=True)``, and the policy is rebuilt from the env's own spaces, its
  layer sizes read off the weights. A policy that cannot be rebuilt so (a custom policy class, a
  non-default activation) is refused with the reason, unless the user trusts the file
  (``--trust`` on the command line, or ``[trust=true]`` in the spec): then SB3's own ``load``
  unpickles it, which runs the code in it.
* **A torch module exported with** ``torch.export`` (``path/to/policy.pt2``): a graph and its
  weights, no Python code. Its input is the flat observation ``(1, D)`` or the graph's three
  arrays ``(1, N, 13)``, ``(1, P, 4)``, ``(1, 11)``; its output the action logits ``(1, A)``.
  :func:`export_policy` writes one, with the metadata this loader checks: how it reads the
  observation, and the flat columns it was trained on. TorchRL modules and RLlib's RLModules
  are torch modules: export them and evaluate them here.
* **An RLlib checkpoint** (a folder: an algorithm's checkpoint, or one RLModule's) of the
  RLlib adapter's module (:class:`agents.interop.rllib_env.MaskedActorCritic`): its
  ``module_state.pkl`` is read by an unpickler that builds nothing but arrays (anything else
  in the file is refused, named), the actor rebuilt from the weights. A module of another
  class: export it (:func:`export_policy`), or trust the file to unpickle it whole.

Every loader checks the flat column layout the policy records (``flat_columns`` of the
vertiport it was trained on) against the vertiport it plays, when the env is bound, and
refuses a policy that reads other columns. Illegal actions are masked before the choice:
the greedy action among the legal ones.

Specs: ``model.zip``, ``model.zip[trust=true]``, ``policy.pt2``, ``path/to/checkpoint``
(a folder; ``[module=NAME]`` where it holds several modules) (the registry,
:mod:`agents.controllers.registry`).
"""

from __future__ import annotations

import io
import json
import os
import pickle
import zipfile
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from agents.common.specs import TRUST_VARIABLE, rllib_module_state
from agents.controllers.base import Controller

__all__ = ["ForeignPolicyError", "METADATA", "ExportedPolicyController", "RLlibController",
           "SB3Controller", "export_policy", "metadata_for", "trusted"]

#: The name of the metadata entry a loader reads (in an SB3 zip, in a ``.pt2``'s extra files).
METADATA = "marl_vertiport.json"
GRAPH_KEYS = ("evtol_nodes", "port_nodes", "self")


class ForeignPolicyError(ValueError):
    """A policy file that cannot be played here; the message names the file and why."""


def trusted(trust: bool | None = None) -> bool:
    """Whether a file may be unpickled: ``trust`` where the spec says, else ``--trust`` (the
    environment variable it sets, :data:`agents.common.specs.TRUST_VARIABLE`)."""
    if trust is not None:
        return bool(trust)
    return os.environ.get(TRUST_VARIABLE, "") == "1"


#: What to say where a file only loads by unpickling.
TRUST_HINT = "use --trust (or [trust=true] in the spec) to unpickle it, which runs its code"


def _sim_of(env: Any) -> Any:
    """The simulator under ``env``: any of the vertiport's envs, wrapped (Gymnasium, PettingZoo,
    SuperSuit, RLlib's ``PettingZooEnv``) or not, or a simulator itself."""
    from marl_vertiport.sim import VertiportSim

    seen = 0
    while not isinstance(env, VertiportSim) and seen < 20:
        inner = getattr(getattr(env, "unwrapped", None), "sim", None)
        if isinstance(inner, VertiportSim):
            return inner
        env = next((getattr(env, a) for a in ("env", "par_env", "aec_env")
                    if getattr(env, a, None) is not None), None)
        seen += 1
        if env is None:
            break
    if not isinstance(env, VertiportSim):
        raise ValueError("expected a vertiport env or simulator (marl_vertiport)")
    return env


def metadata_for(env: Any, observation: str = "flat") -> dict[str, Any]:
    """What a policy trained on ``env`` (any of the vertiport's envs, or its simulator) should
    record: how it reads the observation (``"flat"`` or ``"graph"``), and the vertiport's flat
    columns."""
    from marl_vertiport.flat import flat_columns

    if observation not in ("flat", "graph"):
        raise ValueError(f"observation must be 'flat' or 'graph', got {observation!r}")
    return {"observation": observation, "columns": flat_columns(_sim_of(env))}


class _Flat(Controller):
    """What every foreign policy shares: the flat view of an observation (the env's one
    flattener, clipped into its bounds once the env is bound) and the check of the columns."""

    pure_act = True

    def __init__(self, path: Path, meta: dict[str, Any] | None) -> None:
        self.path, self.meta = path, meta or {}
        self.name = str(path)
        self._flattener = None

    def bind(self, sim: Any) -> None:
        from marl_vertiport.flat import _Flattener

        self._flattener = _Flattener(sim)
        recorded = self.meta.get("columns")
        if recorded is not None and list(recorded) != list(self._flattener.columns):
            diff = next((i for i, (a, b) in enumerate(zip(recorded, self._flattener.columns))
                         if a != b), min(len(recorded), len(self._flattener.columns)))
            raise ForeignPolicyError(
                f"{self.path}: trained on other flat columns than this vertiport's "
                f"({len(recorded)} against {len(self._flattener.columns)}; first difference at "
                f"column {diff}): a flat policy plays only the vertiport it was trained on")

    def flat(self, observation: dict) -> np.ndarray:
        from marl_vertiport.flat import flatten_observation

        if self._flattener is not None:
            return self._flattener(observation)
        return flatten_observation(observation)

    @staticmethod
    def greedy(logits: np.ndarray, mask: np.ndarray) -> int:
        legal = np.flatnonzero(mask)
        return int(legal[np.argmax(np.asarray(logits, dtype=float)[legal])])


# ====================================================================== Stable-Baselines3
def _sb3_parts(path: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any] | None]:
    """The zip's ``data`` (JSON), its policy weights (weights only) and our metadata, if any."""
    import torch

    try:
        with zipfile.ZipFile(path) as z:
            data = json.loads(z.read("data"))
            with z.open("policy.pth") as fh:
                weights = torch.load(fh, map_location="cpu", weights_only=True)
            meta = json.loads(z.read(METADATA)) if METADATA in z.namelist() else None
    except FileNotFoundError:
        raise ForeignPolicyError(f"{path}: no such file") from None
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError) as exc:
        raise ForeignPolicyError(f"{path}: not a Stable-Baselines3 model zip ({exc})") from None
    except Exception as exc:  # torch refuses a policy.pth that is not weights only
        raise ForeignPolicyError(f"{path}: policy.pth does not load as weights only "
                                 f"({' '.join(str(exc).split())[:200]}); {TRUST_HINT}") from None
    return data, weights, meta


def _sb3_data(path: Path) -> dict[str, Any]:
    try:
        with zipfile.ZipFile(path) as z:
            return json.loads(z.read("data"))
    except FileNotFoundError:
        raise ForeignPolicyError(f"{path}: no such file") from None
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError) as exc:
        raise ForeignPolicyError(f"{path}: not a Stable-Baselines3 model zip ({exc})") from None


def _zip_metadata(path: Path) -> dict[str, Any] | None:
    with zipfile.ZipFile(path) as z:
        return json.loads(z.read(METADATA)) if METADATA in z.namelist() else None


def _layer_sizes(weights: dict[str, Any], net: str) -> list[int]:
    sizes, k = [], 0
    while f"mlp_extractor.{net}.{k}.weight" in weights:
        sizes.append(int(weights[f"mlp_extractor.{net}.{k}.weight"].shape[0]))
        k += 2  # Linear, activation, Linear, ...
    return sizes


class SB3Controller(_Flat):
    """A Stable-Baselines3 ``PPO`` or ``MaskablePPO`` model (module docstring); greedy."""

    def __init__(self, path: str | Path, trust: bool | None = None) -> None:
        path = Path(path)
        trust = trusted(trust)
        if trust:
            data, weights, meta = _sb3_data(path), {}, _zip_metadata(path)
        else:
            data, weights, meta = _sb3_parts(path)
        super().__init__(path, meta)
        policy_class = data.get("policy_class") or {}
        module = str(policy_class.get("__module__", ""))
        self.maskable = "maskable" in module
        kwargs = data.get("policy_kwargs")
        custom = isinstance(kwargs, dict) and ":serialized:" in kwargs
        if trust:
            self.policy = self._load_trusted(path)
            return
        if custom or not module.startswith(("stable_baselines3", "sb3_contrib")):
            raise ForeignPolicyError(
                f"{path}: its policy ({module or 'unknown class'}, policy_kwargs "
                f"{'set' if custom else 'default'}) cannot be rebuilt from its weights alone; "
                f"{TRUST_HINT}")
        self.policy = self._rebuild(path, data, weights)

    def _rebuild(self, path: Path, data: dict[str, Any], weights: dict[str, Any]) -> Any:
        import gymnasium
        import torch

        try:
            n_obs = int(weights["mlp_extractor.policy_net.0.weight"].shape[1])
            n_act = int(weights["action_net.weight"].shape[0])
        except KeyError as exc:
            raise ForeignPolicyError(f"{path}: not an MlpPolicy's weights (no {exc})") from None
        obs_space = gymnasium.spaces.Box(-np.inf, np.inf, (n_obs,), np.float32)
        act_space = gymnasium.spaces.Discrete(n_act)
        net_arch = {"pi": _layer_sizes(weights, "policy_net"), "vf": _layer_sizes(weights, "value_net")}
        if self.maskable:
            from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy as cls
        else:
            from stable_baselines3.common.policies import ActorCriticPolicy as cls
        policy = cls(obs_space, act_space, lr_schedule=lambda _: 0.0, net_arch=net_arch)
        try:
            policy.load_state_dict(weights, strict=True)
        except RuntimeError as exc:
            raise ForeignPolicyError(f"{path}: the weights do not fit a default MlpPolicy "
                                     f"({exc.args[0].splitlines()[0]}); {TRUST_HINT}") from None
        policy.set_training_mode(False)
        self.n_obs = n_obs
        return policy.to(torch.device("cpu"))

    def _load_trusted(self, path: Path) -> Any:
        try:
            if self.maskable:
                from sb3_contrib import MaskablePPO as algo
            else:
                from stable_baselines3 import PPO as algo
        except ImportError:
            raise ForeignPolicyError(f"{path}: needs the sb3 extra (pip install -e '.[sb3]')") from None
        model = algo.load(path, device="cpu")
        self.n_obs = int(np.prod(model.observation_space.shape))
        return model.policy

    def act(self, observation: dict) -> int:
        import torch

        flat = self.flat(observation)
        if flat.shape[0] != self.n_obs:
            raise ForeignPolicyError(f"{self.path}: reads {self.n_obs} columns, this vertiport's "
                                     f"flat observation has {flat.shape[0]}")
        with torch.no_grad():
            dist = self.policy.get_distribution(torch.as_tensor(flat[None]))
            logits = dist.distribution.logits[0].numpy()
        return self.greedy(logits, observation["action_mask"])


# ====================================================================== torch.export
def export_policy(module: Any, path: str | Path, env: Any, observation: str = "flat") -> Path:
    """Export ``module`` (a torch module from the observation to the action logits ``(1, A)``;
    module docstring) to ``path`` (``.pt2``) with ``torch.export``, and the metadata
    (:func:`metadata_for`) a loader checks. ``env`` is the vertiport env it was trained on."""
    import torch

    path = Path(path)
    meta = metadata_for(env, observation)
    sim = env.unwrapped.sim
    if observation == "flat":
        example = (torch.zeros(1, len(meta["columns"])),)
    else:
        obs = env.unwrapped._builder.observe(sim.acting)["observation"]
        example = tuple(torch.as_tensor(np.asarray(obs[k], dtype=np.float32))[None]
                        for k in GRAPH_KEYS)
    program = torch.export.export(module.eval(), example)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    torch.export.save(program, str(tmp), extra_files={METADATA: json.dumps(meta)})
    tmp.replace(path)
    return path


class ExportedPolicyController(_Flat):
    """A torch module exported with ``torch.export`` (module docstring); greedy."""

    def __init__(self, path: str | Path) -> None:
        import torch

        path = Path(path)
        extra = {METADATA: ""}
        try:
            program = torch.export.load(str(path), extra_files=extra)
        except FileNotFoundError:
            raise ForeignPolicyError(f"{path}: no such file") from None
        except Exception as exc:
            raise ForeignPolicyError(f"{path}: not a torch.export program ({exc})") from None
        try:
            meta = json.loads(extra[METADATA]) if extra[METADATA] else {}
        except json.JSONDecodeError:
            raise ForeignPolicyError(f"{path}: its {METADATA} is not JSON") from None
        super().__init__(path, meta)
        self.observation = self.meta.get("observation", "flat")
        if self.observation not in ("flat", "graph"):
            raise ForeignPolicyError(f"{path}: observation {self.observation!r} is neither "
                                     "'flat' nor 'graph'")
        self.module = program.module()

    def act(self, observation: dict) -> int:
        import torch

        if self.observation == "flat":
            inputs: Sequence[Any] = (torch.as_tensor(self.flat(observation)[None]),)
        else:
            inputs = tuple(torch.as_tensor(np.asarray(observation["observation"][k],
                                                      dtype=np.float32))[None] for k in GRAPH_KEYS)
        with torch.no_grad():
            logits = self.module(*inputs)
        return self.greedy(np.asarray(logits).reshape(-1), observation["action_mask"])


# ====================================================================== RLlib
class _ArraysOnly(pickle.Unpickler):
    """Unpickles a state of arrays (dicts, lists, numbers, strings, numpy arrays of numbers)
    and nothing else: any other global the file names is refused, so no code of the file runs.
    """

    ALLOWED = {("collections", "OrderedDict"), ("numpy", "dtype"), ("numpy", "ndarray"),
               ("numpy._core.numeric", "_frombuffer"), ("numpy.core.numeric", "_frombuffer"),
               ("numpy._core.multiarray", "_reconstruct"),
               ("numpy.core.multiarray", "_reconstruct")}

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"it names {module}.{name}, which is not an array")
        return super().find_class(module, name)


def _rllib_state(path: Path, trust: bool) -> dict[str, Any]:
    raw = path.read_bytes()
    try:
        state = pickle.loads(raw) if trust else _ArraysOnly(io.BytesIO(raw)).load()
    except pickle.UnpicklingError as exc:
        raise ForeignPolicyError(f"{path}: not weights only ({exc}); {TRUST_HINT}") from None
    except Exception as exc:
        raise ForeignPolicyError(f"{path}: does not unpickle ({type(exc).__name__}: {exc})") from None
    if not isinstance(state, dict):
        raise ForeignPolicyError(f"{path}: holds a {type(state).__name__}, not an RLModule's state")
    bad = [k for k, v in state.items() if isinstance(v, np.ndarray) and v.dtype == object]
    if bad:
        raise ForeignPolicyError(f"{path}: {bad[0]!r} is an array of objects, not of numbers")
    return state


class RLlibController(_Flat):
    """The actor of an RLlib checkpoint of :class:`agents.interop.rllib_env.MaskedActorCritic`
    (module docstring): ``symlog`` of the flat observation without the mask's columns (what
    :class:`marl_vertiport.flat.FlatAEC` calls ``"observations"``) through its ``pi`` MLP;
    greedy."""

    def __init__(self, path: str | Path, module: str | None = None,
                 trust: bool | None = None) -> None:
        import torch

        from agents.common.nets import mlp_from_weights
        from agents.common.specs import AgentSpecError

        folder = Path(path)
        try:
            state_file = rllib_module_state(folder, module)
        except AgentSpecError as exc:
            raise ForeignPolicyError(str(exc)) from None
        meta_file = next((d / METADATA for d in (state_file.parent, *state_file.parents)
                          if (d / METADATA).is_file() and folder in (d, *d.parents)), None)
        meta = json.loads(meta_file.read_text()) if meta_file else None
        super().__init__(folder, meta)
        state = _rllib_state(state_file, trusted(trust))
        try:
            self.pi = mlp_from_weights({k: torch.as_tensor(np.asarray(v)) for k, v in
                                        state.items() if k.startswith("pi.")}, "pi.")
        except (KeyError, RuntimeError) as exc:
            raise ForeignPolicyError(
                f"{state_file}: not the RLlib adapter's MaskedActorCritic (no actor 'pi.' of "
                f"tanh layers: {exc}); export another module with export_policy") from None
        self.n_obs = int(self.pi[0].in_features)

    def act(self, observation: dict) -> int:
        import torch

        from agents.common.nets import symlog

        # FlatAEC's "observations": the flat layout without the mask's columns.
        flat = self.flat(observation)[:-len(observation["action_mask"])]
        if flat.shape[0] != self.n_obs:
            raise ForeignPolicyError(f"{self.path}: reads {self.n_obs} columns, this vertiport's "
                                     f"flat observation (without the mask) has {flat.shape[0]}")
        with torch.no_grad():
            logits = self.pi(symlog(torch.as_tensor(flat[None])))[0].numpy()
        return self.greedy(logits, observation["action_mask"])
