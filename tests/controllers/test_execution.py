"""The execution layer (agents/execution/) without Ray: the local backend in this process and
in a worker pool, stopping, a task that raises, the choice of backend, and the one-line error
when the ray extra is missing."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from agents.execution import (
    INTERRUPTED, RAY_EXTRA_HINT, BackendError, LocalBackend, make_backend,
)

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # spawned workers import this module's functions by name
    sys.path.insert(0, str(ROOT))


def square(x: int) -> int:
    return x * x


def fails_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def _collect(backend, fn, tasks, stop_after=None):
    got: dict[int, int] = {}

    def on_result(i, result):
        got[i] = result
        return stop_after is None or len(got) < stop_after

    return backend.run(fn, tasks, on_result), got


@pytest.mark.parametrize("workers", [1, 2])
def test_local_backend_hands_every_result_back_by_index(workers):
    problem, got = _collect(LocalBackend(workers), square, list(range(7)))
    assert problem is None and got == {i: i * i for i in range(7)}


def test_a_stopped_run_hands_out_no_more_work():
    problem, got = _collect(LocalBackend(1), square, list(range(7)), stop_after=2)
    assert problem is None and got == {0: 0, 1: 1}


@pytest.mark.parametrize("workers", [1, 2])
def test_a_task_that_raises_is_named_in_one_line(workers):
    problem, got = _collect(LocalBackend(workers), fails_on_three, [1, 2, 3, 4])
    assert problem is not None and "\n" not in problem
    assert problem.startswith("task 2 failed: ValueError: three is not allowed")
    assert got.get(0) == 1 and 2 not in got


def test_ctrl_c_in_the_driver_keeps_what_finished():
    got: dict[int, int] = {}

    def on_result(i, result):
        got[i] = result
        if len(got) == 2:
            raise KeyboardInterrupt
        return True

    assert LocalBackend(1).run(square, list(range(5)), on_result) == INTERRUPTED
    assert got == {0: 0, 1: 1}


def sleeps(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


def test_ctrl_c_twice_drops_the_tasks_under_way_and_keeps_what_finished(capsys):
    """The first Ctrl-C waits for the tasks under way and says so; a second one ends them at
    once, and the results that came back before are still handed over."""
    import os
    import signal
    import threading
    import time

    got: dict[int, float] = {}

    def on_result(i, result):
        got[i] = result
        if len(got) == 1:
            threading.Timer(2.0, os.kill, (os.getpid(), signal.SIGINT)).start()
            raise KeyboardInterrupt
        return True

    start = time.monotonic()
    assert LocalBackend(2).run(sleeps, [0.0, 300.0, 300.0, 300.0], on_result) == INTERRUPTED
    assert got == {0: 0.0} and time.monotonic() - start < 120
    assert "Ctrl-C again stops them now" in capsys.readouterr().err


def one_thread(x: int) -> int:
    """A task that sets its own torch thread count, as the demonstration days do."""
    import torch

    torch.set_num_threads(1)
    return x


def test_a_task_run_in_this_process_leaves_its_torch_thread_count():
    """A task that sets torch's thread count must not change the driver's (a run's PPO updates
    after its warm start's days would add up differently with one worker than with two)."""
    import torch

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(3)
        problem, got = _collect(LocalBackend(1), one_thread, [1, 2])
        assert problem is None and got == {0: 1, 1: 2}
        assert torch.get_num_threads() == 3
        _collect(LocalBackend(1), fails_on_three, [3])  # also after a task that raised
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)


def test_choice_of_backend_and_its_errors():
    assert isinstance(make_backend("local", 3), LocalBackend) and make_backend("local", 3).slots == 3
    assert make_backend("local", 1).describe() == "local: this process"
    with pytest.raises(BackendError, match="--ray-address needs --backend ray"):
        make_backend("local", 1, "auto")
    with pytest.raises(BackendError, match="use one of local, ray"):
        make_backend("dask")
    with pytest.raises(BackendError, match="--workers must be >= 1"):
        make_backend("local", 0)


@pytest.fixture
def no_ray(monkeypatch):
    """``import ray`` fails as it does where the extra is not installed."""
    monkeypatch.setitem(sys.modules, "ray", None)


def test_missing_ray_extra_is_one_line_saying_how_to_install_it(no_ray, tmp_path, capsys):
    with pytest.raises(BackendError) as err:
        make_backend("ray")
    assert str(err.value) == f"the ray backend needs the optional ray extra: {RAY_EXTRA_HINT}"
    assert "pip install -e '.[ray]'" in str(err.value)
    from agents.evaluate.cli import main as evaluate_main
    from agents.sweep.cli import main as sweep_main

    for main, argv in ((evaluate_main, ["--agents", "random", "--episodes", "1"]),
                       (sweep_main, ["wind", "--episodes", "1"])):
        capsys.readouterr()
        code = main([*argv, "--backend", "ray", "--out", str(tmp_path / "out"), "--no-progress"])
        err_lines = capsys.readouterr().err.strip().splitlines()
        assert code == 2
        assert err_lines == [f"error: the ray backend needs the optional ray extra: "
                             f"{RAY_EXTRA_HINT}"]
    assert not (tmp_path / "out").exists()  # nothing was run or written


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_end_when_their_driver_is_killed(tmp_path):
    """A driver killed outright (SIGKILL: no chance to shut its pool down) leaves no worker
    going on with the queued tasks."""
    import os
    import signal
    import subprocess
    import textwrap
    import time

    (tmp_path / "helper.py").write_text(textwrap.dedent("""
        import os, time
        from pathlib import Path

        def linger(folder):
            Path(folder, str(os.getpid())).write_text("")
            time.sleep(60)
    """))
    pids = tmp_path / "pids"
    pids.mkdir()
    driver = subprocess.Popen(
        [sys.executable, "-c",
         "import sys; from agents.execution import LocalBackend; import helper; "
         f"LocalBackend(2).run(helper.linger, [{str(pids)!r}] * 4, lambda i, r: True)"],
        cwd=tmp_path, env={**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{tmp_path}"})
    deadline = time.time() + 60
    while len(list(pids.iterdir())) < 2 and time.time() < deadline:
        time.sleep(0.2)
    workers = [int(p.name) for p in pids.iterdir()]
    assert len(workers) == 2, "the workers did not start"
    driver.send_signal(signal.SIGKILL)
    driver.wait()

    def alive(pid):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        with open(f"/proc/{pid}/stat") as f:  # a zombie waiting to be reaped has ended
            return f.read().split(")")[-1].split()[0] != "Z"

    deadline = time.time() + 15
    while any(alive(pid) for pid in workers) and time.time() < deadline:
        time.sleep(0.2)
    assert not any(alive(pid) for pid in workers)
