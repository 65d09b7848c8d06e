"""closest_approach (paper eqs. 3-4) and segment distances, on cases worked by hand."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from marl_vertiport import closest_approach
from marl_vertiport.sim.geometry import (
    cpa, segment_distance, segments_within, swept_min_distance, swept_min_distance_pair,
)


def test_crossing_paths_meet_at_the_intersection():
    # A at (-10, 0) flying +x at 2 m/s, B at (0, -10) flying +y at 2 m/s: both reach the
    # origin at t = 5 s, so they collide (D_min = 0).
    t, d = closest_approach(np.array([-10.0, 0.0]), np.array([2.0, 0.0]),
                            np.array([0.0, -10.0]), np.array([0.0, 2.0]))
    assert t == pytest.approx(5.0)
    assert d == pytest.approx(0.0, abs=1e-12)


def test_crossing_paths_with_offset_timing():
    # B starts 2 m further back: dp = (-10, 12), dv = (2, -2); t = -(dp.dv)/|dv|^2 = 44/8.
    t, d = closest_approach(np.array([-10.0, 0.0]), np.array([2.0, 0.0]),
                            np.array([0.0, -12.0]), np.array([0.0, 2.0]))
    assert t == pytest.approx(5.5)
    # at t = 5.5: A at (1, 0), B at (0, -1) -> D = sqrt(2)
    assert d == pytest.approx(np.sqrt(2.0))


def test_parallel_same_speed_keeps_distance():
    t, d = closest_approach(np.array([0.0, 0.0]), np.array([3.0, 0.0]),
                            np.array([0.0, 4.0]), np.array([3.0, 0.0]))
    assert t == 0.0
    assert d == pytest.approx(4.0)


def test_parallel_overtaking():
    # A behind B on the same line, 2 m/s faster: closes 10 m in 5 s.
    t, d = closest_approach(np.array([0.0, 0.0]), np.array([5.0, 0.0]),
                            np.array([10.0, 0.0]), np.array([3.0, 0.0]))
    assert t == pytest.approx(5.0)
    assert d == pytest.approx(0.0, abs=1e-12)


def test_diverging_gives_negative_time():
    # Moving apart head-away: closest approach was in the past.
    t, d = closest_approach(np.array([0.0, 0.0]), np.array([-1.0, 0.0]),
                            np.array([4.0, 0.0]), np.array([1.0, 0.0]))
    assert t == pytest.approx(-2.0)
    assert d == pytest.approx(0.0, abs=1e-12)


def test_identical_velocities():
    t, d = closest_approach(np.array([1.0, 1.0]), np.array([2.0, -1.0]),
                            np.array([4.0, 5.0]), np.array([2.0, -1.0]))
    assert (t, d) == (0.0, pytest.approx(5.0))


def test_scalar_core_matches_the_public_function():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p1, v1, p2, v2 = rng.normal(size=(4, 2))
        t, d = closest_approach(p1, v1, p2, v2)
        assert cpa((p1 - p2).tolist(), (v1 - v2).tolist()) == (t, d)
    # 3-D works the same way: vertical separation counts.
    t, d = closest_approach(np.array([0.0, 0, 0]), np.array([1.0, 0, 0]),
                            np.array([5.0, 0, 4]), np.array([-1.0, 0, 0]))
    assert (t, d) == (pytest.approx(2.5), pytest.approx(4.0))


def test_segment_distance():
    a0, a1 = (0.0, 0.0), (10.0, 0.0)
    assert segment_distance(a0, a1, (5.0, -5.0), (5.0, 5.0)) == 0.0  # crossing
    assert segment_distance(a0, a1, (0.0, 3.0), (10.0, 3.0)) == pytest.approx(3.0)  # parallel
    assert segment_distance(a0, a1, (12.0, 0.0), (15.0, 0.0)) == pytest.approx(2.0)  # collinear gap
    assert segment_distance(a0, a1, (5.0, 2.0), (5.0, 2.0)) == pytest.approx(2.0)  # a point
    assert segment_distance(a0, a1, (13.0, 4.0), (20.0, 9.0)) == pytest.approx(5.0)  # end to end
    assert segment_distance((1.0, 1.0), (1.0, 1.0), (4.0, 5.0), (4.0, 5.0)) == pytest.approx(5.0)


def test_swept_min_distance_catches_a_pass_between_samples():
    # Two vehicles swap places in one interval: the end points are 4 m apart but they pass
    # 1 m from each other halfway.
    start = np.array([[-2.0, 0.5, 0.0], [2.0, -0.5, 0.0]])
    end = np.array([[2.0, 0.5, 0.0], [-2.0, -0.5, 0.0]])
    d = swept_min_distance(start, end, np.array([0]), np.array([1]))
    assert d[0] == pytest.approx(1.0)


def test_scalar_and_array_swept_distances_agree():
    rng = np.random.default_rng(5)
    start, end = rng.normal(scale=5, size=(8, 3)), rng.normal(scale=5, size=(8, 3))
    end[3] = start[3]  # a vehicle standing still
    end[5] = start[5] + (end[4] - start[4])  # same motion as vehicle 4
    pi, pj = np.triu_indices(8, k=1)
    array = swept_min_distance(start, end, pi, pj)
    for k, (a, b) in enumerate(zip(pi, pj)):
        assert swept_min_distance_pair(tuple(start[a]), tuple(end[a]), tuple(start[b]),
                                       tuple(end[b])) == pytest.approx(array[k], abs=1e-12)


def test_dot_and_length_add_the_products_left_to_right_in_plain_arithmetic():
    from marl_vertiport.sim.geometry import dot, length

    rng = np.random.default_rng(3)
    for n in (2, 3):
        for _ in range(2000):
            u, v = rng.normal(size=n) * 37.0, rng.normal(size=n) * 0.3
            expected = u[0] * v[0] + u[1] * v[1] + (u[2] * v[2] if n == 3 else 0.0)
            assert dot(u, v) == expected
            assert length(u) == np.sqrt(u[0] * u[0] + u[1] * u[1] + (u[2] * u[2] if n == 3 else 0.0))


BLAS_CALLS = {"dot", "inner", "vdot", "matmul", "tensordot", "einsum_path"}


def test_the_simulator_and_the_rule_controllers_hand_nothing_to_blas():
    """numpy's BLAS picks its kernel by the CPU (a fused multiply-add on AVX-512, none on
    AVX2), so a product of vectors there gives other last bits on other machines: no ``@``,
    no ``np.dot``-like call and no ``np.linalg.norm`` of a whole vector (without ``axis``) in
    the code whose numbers the shipped results are."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    files = [*sorted((root / "marl_vertiport").rglob("*.py")),
             *sorted((root / "agents" / "controllers").rglob("*.py"))]
    found = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            where = f"{path.relative_to(root)}:{getattr(node, 'lineno', '?')}"
            if isinstance(node, (ast.BinOp, ast.AugAssign)) and isinstance(node.op, ast.MatMult):
                found.append(f"{where}: @")
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                name = node.func.attr
                if name in BLAS_CALLS:
                    found.append(f"{where}: {name}()")
                elif name == "norm" and not any(k.arg == "axis" for k in node.keywords):
                    found.append(f"{where}: norm() of a whole vector")
    assert found == []


def _cpu_flags() -> set[str]:
    from pathlib import Path

    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def test_a_day_is_the_same_on_the_avx2_and_the_avx512_blas_kernels():
    """A day whose reward differed in its last bits between the two kernels (machines)
    before the simulator stopped using BLAS, played in fresh processes with each kernel."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    if not {"avx512f", "avx512dq", "avx512bw", "avx512vl", "fma", "avx2"} <= _cpu_flags():
        pytest.skip("needs a CPU that runs both OpenBLAS kernels (AVX-512)")
    code = ("from agents.evaluate.episodes import run_task\n"
            "from agents.evaluate.settings import EpisodeTask\n"
            "m = run_task(EpisodeTask('dispatcher', 'paper_uncertain_10', 0, 1000100, ())).metrics\n"
            "print(repr(m['total_reward']), repr(m['mean_battery_pct']), m['steps'])")
    out = {}
    for kernel in ("Haswell", "SkylakeX"):
        env = {**os.environ, "OPENBLAS_CORETYPE": kernel}
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=300, env=env, cwd=Path(__file__).resolve().parents[2])
        assert run.returncode == 0, run.stderr[-2000:]
        out[kernel] = run.stdout.strip()
    assert out["Haswell"] == out["SkylakeX"] and out["Haswell"].endswith(" 1440")


_grid = st.integers(-40, 40).map(lambda k: k / 4.0)  # metres, on a quarter-metre grid
_xy = st.tuples(_grid, _grid)


@settings(max_examples=400, deadline=None)
@given(a0=_xy, a1=_xy, b0=_xy, b1=_xy, limit=st.integers(0, 40).map(lambda k: k / 4.0))
def test_segments_within_says_what_segment_distance_says(a0, a1, b0, b1, limit):
    """The early-exit test of the conflict probe answers ``segment_distance < limit`` exactly,
    on a grid where distances often equal the limit."""
    assert segments_within(a0, a1, b0, b1, limit) == (segment_distance(a0, a1, b0, b1) < limit)
