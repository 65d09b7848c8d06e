"""The benchmark on a tiny budget: it runs end to end and reports every field (no timing is
asserted)."""

import json

from agents.bench import main


def test_bench_smoke(tmp_path):
    report = tmp_path / "performance.md"
    assert main(["--steps", "200", "--repeats", "2", "--configs", "paper", "large",
                 "--vector-steps", "10", "--copies", "2", "--train-iterations", "1",
                 "--out", str(tmp_path), "--report", str(report)]) == 0
    data = json.loads((tmp_path / "bench.json").read_text())
    assert {(r["api"], r["config"]) for r in data["env"]} == {
        ("aec", "paper"), ("single_agent", "paper"), ("aec", "large"), ("single_agent", "large")}
    for row in data["env"]:
        assert row["steps_per_s_min"] <= row["steps_per_s_median"] <= row["steps_per_s_max"]
        assert row["engine_us_per_step"] > 0 and row["overhead_ratio"] > 0
    assert [(r["copies"], r["processes"]) for r in data["vector"]] == [(2, 1), (2, 1), (2, 2)]
    assert [r["batch"] for r in data["inference"]] == [1, 64]
    assert data["training"]["env_steps_per_s"] > 0 and data["training"]["peak_memory_mb"] > 0
    assert data["env_peak_memory_mb"] > 0
    text = report.read_text()
    assert "overhead / engine" in text and "training throughput" in text
