"""The ray backend (agents/execution/ray_backend.py) on a local Ray instance and on a two-node
cluster simulated on this machine: the same per-episode metrics as the local backend for an
evaluation, a warm-start round and a sweep, a node lost mid-sweep, Ctrl-C and failures.

Needs the ray extra (installed by `make test`); skipped with the reason where it is absent."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray", reason="the ray extra is not installed: pip install -e '.[ray]'")

from agents.evaluate import EvalSettings, evaluate  # noqa: E402
from agents.execution import INTERRUPTED, Backend, BackendError, LocalBackend  # noqa: E402
from agents.execution.ray_backend import RayBackend  # noqa: E402
from agents.sweep import parse_sweep, run_sweep  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # Ray workers import this module's functions by name
    sys.path.insert(0, str(ROOT))

SMALL_OBJECT_STORE = 80 * 1024 ** 2


def slow_square(x: int) -> int:
    time.sleep(0.05)
    return x * x


def fails_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def warm_up() -> str:
    """Imports what an episode needs, so that a node's first task is not much slower than the
    others'; returns the node it ran on."""
    import agents.evaluate.episodes  # noqa: F401
    import marl_vertiport.vertiport_v1  # noqa: F401

    return ray.get_runtime_context().get_node_id()


def _metrics(records):
    return [(r.task.agent, r.task.config, r.task.seed, r.task.overrides, r.metrics)
            for r in records]


class TestLocalRayInstance:
    """One Ray instance of the backend's own (2 CPUs) for every test of the class."""

    @pytest.fixture(scope="class")
    @classmethod
    def backend(cls):
        backend = RayBackend(workers=2)
        yield backend
        backend.close()
        assert not ray.is_initialized()  # it shuts down the instance it started

    def test_same_per_episode_metrics_as_the_local_backend(self, backend):
        settings = EvalSettings(agents=("random", "fcfs"), configs=("paper", "paper_uncertain"),
                                episodes=2, overrides=(("schedule.episode_steps", 120),))
        here = evaluate(settings, workers=1, progress=False)
        there = evaluate(settings, progress=False, backend=backend)
        assert here.complete and there.complete
        assert _metrics(there.records) == _metrics(here.records)
        assert there.summary == here.summary  # and so the same tables and figures
        assert backend.describe() == "ray: 1 node, 2 CPUs"

    def test_warm_start_days_are_the_same_on_ray(self, backend):
        from agents.training.demonstrations import DayTask, collect
        from marl_vertiport.config import load_config, to_dict

        env_cfg = to_dict(load_config("paper"))
        tasks = [DayTask(env_cfg, s, steps, "dispatcher", 4, noise=0.2)
                 for s, steps in ((11, 60), (12, 20), (13, 40))]
        one, m1 = collect(tasks, 1, lambda *_: None, "here")
        two, m2 = collect(tasks, backend, lambda *_: None, "ray")
        assert m1 == m2
        for key in one:
            np.testing.assert_array_equal(one[key], two[key])

    def test_ctrl_c_keeps_what_finished_and_cancels_the_rest(self, backend):
        got: dict[int, int] = {}

        def on_result(i, result):
            got[i] = result
            if len(got) == 2:
                raise KeyboardInterrupt
            return True

        assert backend.run(slow_square, list(range(40)), on_result) == INTERRUPTED
        assert len(got) >= 2 and len(got) < 40 and all(v == i * i for i, v in got.items())

    def test_a_task_that_raises_is_named_in_one_line(self, backend):
        got: dict[int, int] = {}
        problem = backend.run(fails_on_three, [1, 2, 3, 4], lambda i, r: got.setdefault(i, r) or True)
        assert problem is not None and "\n" not in problem
        assert "task 2 failed" in problem and "ValueError: three is not allowed" in problem


def test_an_address_where_no_cluster_answers_fails_at_once():
    start = time.perf_counter()
    with pytest.raises(BackendError, match="no Ray cluster answers at 127.0.0.1:1"):
        RayBackend(address="127.0.0.1:1")
    assert time.perf_counter() - start < 10 and not ray.is_initialized()


class KillsANode(Backend):
    """The ray backend, with one node of the cluster removed as soon as a result computed on
    that node comes in (so both nodes have run tasks, and the run is not over)."""

    name = "ray"

    def __init__(self, inner: RayBackend, cluster, node) -> None:
        self.inner, self.cluster, self.node = inner, cluster, node
        self.killed_after: int | None = None

    @property
    def slots(self) -> int:
        return self.inner.slots

    def run(self, fn, tasks, on_result):
        seen = []

        def watch(i, result):
            seen.append(i)
            if self.killed_after is None and self.inner.placements[i] == self.node.node_id:
                self.cluster.remove_node(self.node)
                self.killed_after = len(seen)
            return on_result(i, result)

        return self.inner.run(fn, tasks, watch)


def test_two_node_cluster_sweep_survives_losing_a_node():
    """A sweep's tasks spread over both nodes of a simulated cluster; one node is killed
    mid-run; its tasks are retried on the other and every episode matches the local backend."""
    from ray.cluster_utils import Cluster

    spec = parse_sweep({"agents": ["fcfs", "dispatcher"], "configs": ["paper"],
                        "grid": {"uncertainty.wind_gust_prob": [0.0, 0.2]},
                        "set": {"schedule.episode_steps": 360}, "episodes": 3},
                       "node_loss", "test")
    local = run_sweep(spec, LocalBackend(1), progress=False)
    assert local.complete and len(local.records) == 12
    cluster = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 1, "include_dashboard": False, "object_store_memory": SMALL_OBJECT_STORE})
    try:
        worker = cluster.add_node(num_cpus=1, object_store_memory=SMALL_OBJECT_STORE)
        path = ":".join(p for p in sys.path if p and Path(p).is_dir())  # this module, by name
        ray.init(address=cluster.address, log_to_driver=False,
                 runtime_env={"env_vars": {"PYTHONPATH": path}})
        cluster.wait_for_nodes()
        inner = RayBackend()  # joins the driver's cluster as it is
        assert inner.describe() == "ray: 2 nodes, 2 CPUs"
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        nodes = [n["NodeID"] for n in ray.nodes()]
        warm = ray.remote(warm_up)
        assert ray.get([warm.options(num_cpus=1, scheduling_strategy=NodeAffinitySchedulingStrategy(
            n, soft=False)).remote() for n in nodes]) == nodes
        killer = KillsANode(inner, cluster, worker)
        result = run_sweep(spec, killer, progress=False)
        assert killer.killed_after is not None and killer.killed_after < 12  # mid-run
        assert result.complete, result.error
        assert {worker.node_id} < set(inner.placements.values())  # both nodes ran tasks
        assert _metrics(result.records) == _metrics(local.records)
        assert inner.describe() == "ray: 1 node, 1 CPUs"
    finally:
        ray.shutdown()
        cluster.shutdown()
