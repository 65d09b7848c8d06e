"""What every result file records of where it came from: the code's commit and whether it
differed, the checkpoints that played (by SHA-256) and the machine (agents/common/provenance.py)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from agents.common import provenance as prov
from agents.controllers.registry import SHIPPED_CHECKPOINT

SHORT = ["--set", "schedule.episode_steps=6", "--no-progress", "--workers", "1"]


def test_checkpoint_files_of_agent_specs(tmp_path):
    from agents.common.specs import checkpoint_files

    assert checkpoint_files("gcn") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("gcn[deterministic=false]") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("runs/a/model_9.pt+gcn") == [Path("runs/a/model_9.pt"), SHIPPED_CHECKPOINT]
    assert checkpoint_files("dispatcher") == []
    assert checkpoint_files("examples.custom_agent:ChargeFirst") == []


def test_the_record_names_the_commit_the_dirty_flag_and_each_checkpoints_hash(tmp_path):
    record = prov.provenance(["gcn", "fcfs"])
    head = subprocess.run(["git", "-C", str(prov.REPO_ROOT), "rev-parse", "HEAD"],
                          capture_output=True, text=True)
    if head.returncode == 0:
        assert record["code"]["commit"] == head.stdout.strip()
        assert isinstance(record["code"]["dirty"], bool)
    assert set(record["checkpoints"]) == {"gcn"}
    assert record["checkpoints"]["gcn"] == {"path": "agents/checkpoints/gcn_default.pt",
                                            "sha256": prov.file_sha256(SHIPPED_CHECKPOINT)}
    assert record["machine"]["cores"] >= 1
    line = prov.describe(record)
    assert "gcn_default.pt sha256 " + record["checkpoints"]["gcn"]["sha256"][:16] in line


def test_evaluation_files_carry_the_record(tmp_path):
    from agents.evaluate.cli import main

    out = tmp_path / "out"
    assert main(["--agents", "gcn", "fcfs", "--configs", "paper", "--episodes", "1", *SHORT,
                 "--out", str(out), "--report", str(out / "report.md")]) == 0
    doc = json.loads((out / "results.json").read_text())
    sha = prov.file_sha256(SHIPPED_CHECKPOINT)
    assert doc["provenance"]["checkpoints"]["gcn"]["sha256"] == sha
    assert "fcfs" not in doc["provenance"]["checkpoints"]
    assert f"gcn_default.pt sha256 {sha[:16]}" in (out / "report.md").read_text()
    for figure in ("case_study.png", "action_distribution.png"):
        assert prov.read_png_metadata(out / figure) == doc["provenance"]


def test_sweep_files_carry_the_record(tmp_path):
    from agents.sweep.cli import main

    out = tmp_path / "sweep"
    assert main(["wind", "--agents", "gcn", "--episodes", "1", "--grid",
                 "uncertainty.wind_gust_prob=0,0.1", *SHORT, "--out", str(out)]) == 0
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["provenance"]["checkpoints"]["gcn"]["sha256"] == prov.file_sha256(SHIPPED_CHECKPOINT)
    assert prov.read_png_metadata(out / "sweep.png") == doc["provenance"]


def test_a_png_without_the_record_reads_as_none(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure()
    fig.savefig(tmp_path / "plain.png")
    plt.close(fig)
    assert prov.read_png_metadata(tmp_path / "plain.png") is None
    (tmp_path / "text.png").write_text("not a png")
    assert prov.read_png_metadata(tmp_path / "text.png") is None
