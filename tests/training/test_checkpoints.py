"""What a run's checkpoints are to their readers: a broken or foreign file refused clearly, a
file carrying code never run by any loader, and a checkpoint of one layout flying others."""


import pytest
import torch

from agents.controllers.gcn import CheckpointError, GCNController
from agents.training.pipeline import train

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution
from helpers import tiny_config


class _RunsCode:
    """Unpickling this object calls ``open(path, "w")``: a stand-in for a hostile file."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))

def test_bad_checkpoints_are_refused_clearly(tmp_path):
    bad = tmp_path / "model_3.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        GCNController(bad)
    marker = tmp_path / "ran"
    torch.save({"actor_state_dict": {}, "infos": _RunsCode(str(marker))}, tmp_path / "hostile.pt")
    with pytest.raises(CheckpointError, match="corrupt or not a torch file"):
        GCNController(tmp_path / "hostile.pt")
    assert not marker.exists()  # the file's pickled call was not made
    torch.save({"foo": 1}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not a marl_vertiport training checkpoint"):
        GCNController(tmp_path / "other.pt")
    # A checkpoint made with another observation schema is refused, both schemas named.
    small = tmp_path / "small.yaml"
    small.write_text("base: paper\nfleet_size: 3\n")
    final = train(tiny_config("single_agent", iterations=1, env_config=str(small)),
                  tmp_path / "small", log=lambda *_: None, evaluate=False)
    data = torch.load(final, weights_only=True)
    data["infos"]["marl_vertiport"]["feature_schema"]["ports"].append("altitude_m")
    torch.save(data, tmp_path / "other_schema.pt")
    with pytest.raises(CheckpointError, match="altitude_m"):
        GCNController(tmp_path / "other_schema.pt")

def test_checkpoint_of_one_layout_acts_legally_a_full_day_on_others(tmp_path):
    """Trained on the paper's ports with 3 eVTOLs, it flies a whole day on a 5-eVTOL layout
    with two chargers and on a 6-eVTOL layout with 14 nodes; every action it takes is legal
    (the env raises on an illegal one)."""
    from agents.controllers.episode import run_aec_episode
    from marl_vertiport import vertiport_v1

    small = tmp_path / "small.yaml"
    small.write_text("base: paper\nfleet_size: 3\n")
    final = train(tiny_config("multi_agent", iterations=1, env_config=str(small)),
                  tmp_path / "small", log=lambda *_: None, evaluate=False)
    ctl = GCNController(final)
    for config, steps in (("mid", 1440), ("twin", 2880)):  # twin decides twice a minute
        metrics = run_aec_episode(vertiport_v1.env(config=config), ctl, 1_000_000)
        assert metrics["steps"] == steps

def test_a_file_carrying_code_is_refused_by_every_loader_and_never_run(tmp_path, capsys):
    """A pickle whose loading would create a file, handed to evaluation, rendering, a resumed
    run and a resumed warm start: each refuses it with a one-line error; the file never exists."""
    from agents.evaluate import main as evaluate_main
    from agents.training.cli import main as train_main
    from agents.render import main as render_main

    marker = tmp_path / "ran"
    hostile = {"actor_state_dict": {}, "critic_state_dict": {}, "optimizer_state_dict": {},
               "iter": 1, "infos": _RunsCode(str(marker))}
    evil = tmp_path / "evil.pt"
    torch.save(hostile, evil)

    assert evaluate_main(["--agents", str(evil), "--episodes", "1", "--out", str(tmp_path / "e")]) == 2
    assert "corrupt or not a torch file" in capsys.readouterr().err
    assert render_main(["--agent", str(evil), "--minutes", "2", "--out", str(tmp_path / "r.gif")]) == 2
    assert "corrupt or not a torch file" in capsys.readouterr().err

    # A real run's last checkpoint replaced by the hostile file, then resumed.
    run = tmp_path / "run"
    train(tiny_config("single_agent", iterations=1, env_config="small"), run,
          log=lambda *_: None, evaluate=False)
    (last,) = sorted(run.glob("model_*.pt"))[-1:]
    torch.save(hostile, last)
    assert train_main(["--resume", str(run), "--no-eval"]) == 2
    err = capsys.readouterr().err
    assert f"checkpoint {last} cannot be loaded into this run" in err and len(err.strip().splitlines()) == 1

    # A hostile warm-start progress file (what a run stopped during its warm start resumes from;
    # test_run_killed_during_the_warm_start_resumes_it goes through that path).
    from agents.training.imitation import load_warm_start_state

    torch.save({"next_round": 1, "data": _RunsCode(str(marker))}, run / "warmstart_state.pt")
    with pytest.raises(ValueError, match="not a readable warm-start state.*tensors and plain data only"):
        load_warm_start_state(run / "warmstart_state.pt")
    assert not marker.exists()


def test_the_slim_copy_keeps_the_weights_and_metadata_and_drops_the_optimizer(tmp_path):
    from agents.training.checkpoints import SHIPPED_KEYS, slim_checkpoint

    final = train(tiny_config("multi_agent", iterations=1), tmp_path / "run", log=lambda *_: None,
                  evaluate=False)
    slim_checkpoint(final, tmp_path / "ship.pt")
    full = torch.load(final, weights_only=True)
    slim = torch.load(tmp_path / "ship.pt", weights_only=True)
    assert "optimizer_state_dict" in full and tuple(slim) == SHIPPED_KEYS
    for group in ("actor_state_dict", "critic_state_dict"):
        assert slim[group].keys() == full[group].keys()
        assert all(torch.equal(slim[group][k], full[group][k]) for k in full[group])
    assert slim["infos"] == full["infos"] and slim["iter"] == full["iter"]
    GCNController(tmp_path / "ship.pt")
    torch.save({"actor_state_dict": {}}, tmp_path / "part.pt")
    with pytest.raises(ValueError, match="not a training checkpoint"):
        slim_checkpoint(tmp_path / "part.pt", tmp_path / "never.pt")
    assert not (tmp_path / "never.pt").exists()
