"""Policies trained in other libraries as controllers (agents/controllers/foreign.py): an SB3
``.zip`` (MaskablePPO and PPO), a ``torch.export`` ``.pt2`` over the flat or the graph
observation, an RLlib checkpoint folder; each read as weights only, its flat columns checked,
playing in the registry's every tool; a hostile file refused without running it, unless
trusted; a controller object in memory evaluated beside the dispatcher.

SB3 and RLlib need their extras (installed by ``make test``); their tests are skipped, with the
reason, where the extra is absent."""

from __future__ import annotations

import io
import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.common.specs import TRUST_VARIABLE, AgentSpecError
from agents.controllers.episode import prepare, run_episode
from agents.controllers.foreign import (
    METADATA, ExportedPolicyController, ForeignPolicyError, RLlibController, SB3Controller,
    export_policy, metadata_for,
)
from agents.controllers.registry import in_memory, make_controller
from marl_vertiport import vertiport_v1

SHORT = {"schedule.episode_steps": 48}
SB3_MISSING = "the sb3 extra is not installed: pip install -e '.[sb3]'"
RLLIB_MISSING = "the rllib extra is not installed: pip install -e '.[rllib]'"


@pytest.fixture(autouse=True)
def one_thread(monkeypatch):
    monkeypatch.delenv(TRUST_VARIABLE, raising=False)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


class Marker:
    """Unpickling this writes a file: the proof that a loader ran a file's code."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.write_text, (self.path, "ran"))


def _observations(config: str = "paper", days: int = 1, steps: int = 48):
    """AEC observations of a few turns of the dispatcher's day, and the env."""
    env = vertiport_v1.env(config=config, **SHORT)
    dispatcher = make_controller("dispatcher")
    seen = []
    for day in range(days):
        env.reset(seed=day)
        prepare(dispatcher, env, day)
        for agent in env.agent_iter(steps):
            obs, _, term, trunc, _ = env.last()
            if term or trunc:
                env.step(None)
                continue
            seen.append(obs)
            env.step(dispatcher.act(obs))
    return env, seen


def _legal_day(controller, config: str = "paper") -> dict:
    env = vertiport_v1.env(config=config, **SHORT)
    return run_episode(env, controller, seed=3)


# -- Stable-Baselines3 ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sb3_models(tmp_path_factory):
    """A MaskablePPO saved by the recipe (with the columns) and a plain PPO saved by SB3 (not
    trained: without masks it would step illegal actions, which the env refuses)."""
    pytest.importorskip("sb3_contrib", reason=SB3_MISSING)
    from stable_baselines3 import PPO

    from agents.interop import sb3

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("sb3")
    maskable = sb3.train("paper", steps=256, seed=0, n_steps=128, batch_size=64, n_epochs=1,
                         **SHORT)
    sb3.save(maskable, folder / "maskable.zip")
    ppo = PPO("MlpPolicy", sb3.make_env("paper", **SHORT), n_steps=128, batch_size=64,
              n_epochs=1, seed=0, device="cpu", policy_kwargs={"net_arch": [32]})
    ppo.save(folder / "ppo.zip")
    return folder, maskable, ppo


def test_sb3_zip_plays_as_its_model_predicts(sb3_models):
    folder, maskable, ppo = sb3_models
    env, observations = _observations()
    for name, model, masked in (("maskable.zip", maskable, True), ("ppo.zip", ppo, False)):
        controller = make_controller(str(folder / name))
        assert isinstance(controller, SB3Controller)
        prepare(controller, env, 0)
        flat = controller._flattener
        agree = 0
        for obs in observations:
            action = controller.act(obs)
            assert obs["action_mask"][action] == 1
            kwargs = {"action_masks": obs["action_mask"]} if masked else {}
            expected, _ = model.predict(flat(obs), deterministic=True, **kwargs)
            agree += int(expected) == action or not obs["action_mask"][int(expected)]
        # Where the model's choice is legal, the controller makes it (PPO's may be illegal:
        # the controller then takes the best legal one).
        assert agree == len(observations), name


def test_sb3_zip_records_the_columns_and_a_vertiport_with_others_is_refused(sb3_models, tmp_path):
    folder, _, _ = sb3_models
    with zipfile.ZipFile(folder / "maskable.zip") as z:
        meta = json.loads(z.read(METADATA))
    env = vertiport_v1.env(config="paper")
    assert meta == metadata_for(env, "flat") and meta["observation"] == "flat"
    other = vertiport_v1.env(config="wide")
    controller = make_controller(str(folder / "maskable.zip"))
    other.reset(seed=0)
    with pytest.raises(ForeignPolicyError, match="other flat columns"):
        prepare(controller, other, 0)
    # A model of another vertiport without recorded columns: refused at its first turn.
    plain = tmp_path / "plain.zip"
    with zipfile.ZipFile(folder / "maskable.zip") as src, zipfile.ZipFile(plain, "w") as dst:
        for item in src.namelist():
            if item != METADATA:
                dst.writestr(item, src.read(item))
    controller = make_controller(str(plain))
    prepare(controller, other, 0)
    with pytest.raises(ForeignPolicyError, match=r"reads \d+ columns, this vertiport.s flat observation has \d+"):
        controller.act(other.observe(other.agent_selection))


def test_sb3_zip_whose_weights_are_a_pickle_is_refused_and_runs_nothing(sb3_models, tmp_path):
    folder, _, _ = sb3_models
    hostile, marker = tmp_path / "hostile.zip", tmp_path / "ran.txt"
    with zipfile.ZipFile(folder / "maskable.zip") as src, zipfile.ZipFile(hostile, "w") as dst:
        for item in src.namelist():
            if item == "policy.pth":
                buffer = io.BytesIO()
                torch.save({"weights": Marker(marker)}, buffer)
                dst.writestr(item, buffer.getvalue())
            else:
                dst.writestr(item, src.read(item))
    with pytest.raises(AgentSpecError, match="not load as weights only.*--trust"):
        make_controller(str(hostile))
    assert not marker.exists()


def test_sb3_custom_policy_needs_trust_and_trust_loads_it(sb3_models, tmp_path, monkeypatch):
    folder, maskable, _ = sb3_models
    custom = tmp_path / "custom.zip"
    with zipfile.ZipFile(folder / "maskable.zip") as src, zipfile.ZipFile(custom, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "data":
                fields = json.loads(data)
                fields["policy_kwargs"] = {":type:": "<class 'dict'>", ":serialized:": "gAR9lC4="}
                data = json.dumps(fields).encode()
            dst.writestr(item, data)
    with pytest.raises(AgentSpecError, match="cannot be rebuilt.*--trust"):
        make_controller(str(custom))
    monkeypatch.setenv(TRUST_VARIABLE, "1")  # what --trust sets
    trusted = make_controller(str(custom))
    env, observations = _observations()
    prepare(trusted, env, 0)
    rebuilt = make_controller(str(folder / "maskable.zip"))
    prepare(rebuilt, env, 0)
    assert [trusted.act(o) for o in observations] == [rebuilt.act(o) for o in observations]


def test_not_a_zip_and_a_missing_file_are_named(tmp_path):
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip")
    with pytest.raises(AgentSpecError, match="junk.zip: not a Stable-Baselines3 model zip"):
        make_controller(str(junk))
    with pytest.raises(AgentSpecError, match="absent.zip: no such file"):
        make_controller(str(tmp_path / "absent.zip"))


# -- torch.export ---------------------------------------------------------------------------


class FlatNet(torch.nn.Module):
    def __init__(self, n_in: int, n_out: int) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.net = torch.nn.Linear(n_in, n_out)

    def forward(self, x):
        return self.net(x)


class GraphNet(torch.nn.Module):
    """Mean of the eVTOL rows, mean of the port rows and the self row, to the logits."""

    def __init__(self, n_out: int) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.net = torch.nn.Linear(13 + 4 + 11, n_out)

    def forward(self, evtols, ports, me):
        return self.net(torch.cat([evtols.mean(1), ports.mean(1), me], -1))


def test_exported_module_plays_flat_and_graph_as_the_module_does(tmp_path):
    env, observations = _observations()
    n_actions = len(observations[0]["action_mask"])
    flat_net = FlatNet(len(metadata_for(env)["columns"]), n_actions)
    graph_net = GraphNet(n_actions)
    flat_file = export_policy(flat_net, tmp_path / "flat.pt2", env, "flat")
    graph_file = export_policy(graph_net, tmp_path / "graph.pt2", env, "graph")
    flat, graph = make_controller(str(flat_file)), make_controller(str(graph_file))
    assert isinstance(flat, ExportedPolicyController) and graph.observation == "graph"
    prepare(flat, env, 0)
    prepare(graph, env, 0)
    for obs in observations:
        mask = obs["action_mask"]
        with torch.no_grad():
            want_flat = flat_net(torch.as_tensor(flat._flattener(obs)[None]))[0].numpy()
            arrays = [torch.as_tensor(np.asarray(obs["observation"][k], np.float32))[None]
                      for k in ("evtol_nodes", "port_nodes", "self")]
            want_graph = graph_net(*arrays)[0].numpy()
        for controller, logits in ((flat, want_flat), (graph, want_graph)):
            legal = np.flatnonzero(mask)
            assert controller.act(obs) == legal[np.argmax(logits[legal])]
    assert _legal_day(make_controller(str(graph_file)))["steps"] > 0


def test_a_pt2_that_is_not_an_export_is_named(tmp_path):
    bad = tmp_path / "bad.pt2"
    torch.save({"a": torch.zeros(1)}, bad)
    with pytest.raises(AgentSpecError, match="bad.pt2: not a torch.export program"):
        make_controller(str(bad))


# -- RLlib ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rllib_checkpoint(tmp_path_factory):
    """The RLlib adapter's module, saved as RLlib saves one (``save_to_path``)."""
    pytest.importorskip("ray.rllib", reason=RLLIB_MISSING)
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from agents.interop import rllib_env

    env = rllib_env.make_env("paper", **SHORT)
    agent = env.possible_agents[0]
    module = RLModuleSpec(module_class=rllib_env.MaskedActorCritic,
                          observation_space=env.observation_space[agent],
                          action_space=env.action_space[agent],
                          model_config={"hidden": 32}).build()
    folder = tmp_path_factory.mktemp("rllib") / "checkpoint"
    rllib_env.save_policy(module, folder / "learner_group" / "learner" / "rl_module" / "shared",
                          env)
    return folder, module, env


def test_rllib_checkpoint_plays_as_its_module_does(rllib_checkpoint):
    folder, module, rl_env = rllib_checkpoint
    controller = make_controller(str(folder))
    assert isinstance(controller, RLlibController)
    obs, _ = rl_env.reset(seed=0)
    sim_env = rl_env.env  # the AEC env under RLlib's PettingZooEnv
    prepare(controller, sim_env, 0)
    for _ in range(40):
        (agent,) = obs
        with torch.no_grad():
            batch = {"obs": {k: torch.as_tensor(v)[None] for k, v in obs[agent].items()}}
            logits = module.forward_inference(batch)["action_dist_inputs"][0]
        expected = int(torch.argmax(logits))
        assert controller.act(sim_env.unwrapped.observe(agent)) == expected
        obs, _, _, _, _ = rl_env.step({agent: expected})


def test_rllib_state_naming_code_is_refused_and_runs_nothing(rllib_checkpoint, tmp_path,
                                                              monkeypatch):
    folder, _, _ = rllib_checkpoint
    hostile = tmp_path / "hostile"
    state_file = next(folder.rglob("module_state.pkl"))
    target = hostile / state_file.relative_to(folder)
    target.parent.mkdir(parents=True)
    state = pickle.loads(state_file.read_bytes())
    marker = tmp_path / "ran.txt"
    state["extra"] = Marker(marker)
    target.write_bytes(pickle.dumps(state))
    with pytest.raises(AgentSpecError, match="pathlib.*not an array.*--trust"):
        make_controller(str(hostile))
    assert not marker.exists()
    monkeypatch.setenv(TRUST_VARIABLE, "1")
    make_controller(str(hostile))
    assert marker.read_text() == "ran"  # trusted: the file's code ran, as the user said


def test_rllib_folder_without_a_module_is_named(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(AgentSpecError, match="no RLModule's module_state.pkl"):
        make_controller(str(tmp_path / "empty"))


# -- the tools and Python -------------------------------------------------------------------


def test_every_tool_takes_a_foreign_policy_and_records_its_file(tmp_path, monkeypatch):
    from agents.cli import main

    env, _ = _observations()
    home, elsewhere = tmp_path / "home", tmp_path / "elsewhere"
    elsewhere.mkdir()
    export_policy(FlatNet(len(metadata_for(env)["columns"]), 14), home / "p.pt2", env)
    monkeypatch.chdir(home)
    out = tmp_path / "eval"
    assert main(["evaluate", "--agents", "p.pt2", "dispatcher", "--configs", "paper",
                 "--episodes", "1", "--workers", "1", "--set", "schedule.episode_steps=48",
                 "--out", str(out), "--no-progress"]) == 0
    results = json.loads((out / "results.json").read_text())
    recorded = results["provenance"]["controllers"]["p.pt2"]
    assert recorded["file"] == str((home / "p.pt2").resolve()) and len(recorded["sha256"]) == 64
    monkeypatch.chdir(elsewhere)  # p.pt2 is not here: the record says where it was
    assert main(["worst-day", str(out), "--no-video", "--no-progress"]) == 0
    made = sorted(f.name for f in (out / "worst_day").iterdir())
    assert "p_pt2_paper.timeline.png" in made and not [f for f in made if f.endswith(".gif")]
    assert "| yes |" in (out / "worst_day" / "index.md").read_text()
    timeline = tmp_path / "day.png"
    assert main(["timeline", "--agent", str(home / "p.pt2"), "--config", "paper", "--seed", "5",
                 "--set", "schedule.episode_steps=48", "--out", str(timeline)]) == 0
    assert timeline.stat().st_size > 0


def test_evaluate_a_controller_in_memory_beside_the_dispatcher(tmp_path):
    from agents.evaluate import evaluate

    class TakeFirstLegal:
        def act(self, observation):
            return int(np.flatnonzero(observation["action_mask"])[0])

    evaluation = evaluate(TakeFirstLegal(), configs=("paper",), episodes=2,
                          overrides=tuple(SHORT.items()), out=tmp_path / "mem", progress=False)
    assert evaluation.settings.agents == ("TakeFirstLegal", "dispatcher")
    assert {r.task.agent for r in evaluation.records} == {"TakeFirstLegal", "dispatcher"}
    assert evaluation.error is None and len(evaluation.records) == 4
    results = json.loads((tmp_path / "mem" / "results.json").read_text())
    assert results["provenance"]["controllers"]["TakeFirstLegal"]["in_memory"].endswith(
        "TakeFirstLegal")
    with pytest.raises(AgentSpecError):
        make_controller("TakeFirstLegal")  # the name lives only during the call
    from agents.evaluate import InputError

    with pytest.raises(InputError, match="taken"):
        evaluate(TakeFirstLegal(), name="dispatcher", configs=("paper",), episodes=1)
    with pytest.raises(AgentSpecError, match="no act"):
        with in_memory("x", object()):
            pass


def test_the_registry_and_the_loaders_do_not_import_the_adapters():
    """The registry and the loaders sit below agents.interop: nothing they import, at the top or
    in a function, reaches it (the architecture's layers, tests/tools/test_architecture.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "architecture", Path(__file__).parents[1] / "tools" / "test_architecture.py")
    architecture = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(architecture)
    graph = architecture.import_graph()
    for start in ("agents.controllers.registry", "agents.controllers.foreign"):
        seen, todo = set(), [start]
        while todo:
            module = todo.pop()
            if module not in seen:
                seen.add(module)
                todo.extend(graph.get(module, ()))
        assert not [m for m in seen if m.startswith("agents.interop")], start
    assert os.environ.get(TRUST_VARIABLE) is None
