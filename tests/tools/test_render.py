"""The episode renderer (agents/render/): CLI output, overlay, label placement, errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageSequence

from agents import render
from agents.controllers.random_agent import RandomController
from marl_vertiport import vertiport_v1
from marl_vertiport.render import render_frame
from marl_vertiport.sim.schema import AWAY
from marl_vertiport.sim.physics import VEHICLE_COLOURS

ROOT = Path(__file__).resolve().parents[2]


def _gif(path):
    im = Image.open(path)
    frames = [f.convert("RGB") for f in ImageSequence.Iterator(im)]
    return im, frames


@pytest.fixture
def env():
    e = vertiport_v1.env(config="paper", render_mode="rgb_array")
    yield e
    e.close()


def _advance(env, steps, seed=7):
    """Reset and take ``steps`` random legal steps; returns the simulator."""
    env.reset(seed=seed)
    policy = RandomController(seed)
    for _ in range(steps):
        obs = env.observe(env.agent_selection)
        env.step(policy.act(obs))
    return env.unwrapped.sim


def test_cli_writes_gif_with_expected_frames_and_size(tmp_path, capsys):
    out = tmp_path / "sub" / "tiny.gif"  # the folder is created
    rc = render.main(["--agent", "random", "--minutes", "6", "--size", "320x240", "--fps", "5",
                      "--out", str(out), "--no-progress"])
    assert rc == 0
    im, frames = _gif(out)
    assert len(frames) == 6
    assert im.size == (320, 240)
    assert im.info.get("duration") == 200
    assert all(np.asarray(f).std() > 10 for f in frames)  # not blank
    assert not any(frames[0].tobytes() == f.tobytes() for f in frames[1:])  # the clock moves
    # The video, its decision log (every turn, and the turns with a choice), the timeline of
    # the day so far; no temp file left.
    assert sorted(p.name for p in out.parent.iterdir()) == [
        "tiny.decisions.choices.csv", "tiny.decisions.csv", "tiny.decisions.json", "tiny.gif",
        "tiny.timeline.png"]
    assert "wrote" in capsys.readouterr().err
    log = json.loads((out.parent / "tiny.decisions.json").read_text())
    assert log["meta"]["video"] == "tiny.gif" and len(log["rows"]) == 6


def test_no_decisions_leaves_the_video_alone(tmp_path):
    out = tmp_path / "plain.gif"
    assert render.main(["--agent", "random", "--minutes", "2", "--size", "320x240",
                        "--out", str(out), "--no-progress", "--no-decisions"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.gif", "plain.timeline.png"]


def test_the_decision_strip_shows_recommendation_probabilities_and_masked_reasons(env):
    from agents.controllers.decisions import DecisionLog
    from agents.controllers.registry import make_controller

    policy = make_controller("gcn")
    log = DecisionLog(policy)
    frames = render.record_episode(env, policy, 5, lambda s: render.FrameComposer(s, 640, 480),
                                   start_step=0, n_steps=8, every=1, progress=False, log=log)
    assert len(frames) == 8 and len(log.rows) == 8
    composer = render.FrameComposer(env.unwrapped.sim, 640, 480)
    row = next(r for r in log.rows if r["legal"] > 1)
    lines = [text for text, _ in composer.decision_lines(row)]
    assert lines[0].startswith(row["agent"].replace("evtol_", "eVTOL "))
    assert "by gcn:" in lines[0]
    assert lines[1].startswith("policy: ")  # the learned ATC's alternatives, most likely first
    first_alt = next(iter(row["probabilities"]))
    assert render.style.short_action(first_alt) in lines[1]
    masked_line = next(t for t in lines if t.startswith("masked: "))
    assert "status" not in masked_line  # never an option: left out of the strip
    # The strip is drawn over the top of the 3-D view only.
    plain = np.asarray(composer.compose())
    with_strip = np.asarray(composer.compose(decision=row))
    changed = np.flatnonzero((plain != with_strip).any(axis=(1, 2)))
    assert changed.size and changed.max() < 100
    assert not (plain[:, composer.view_w:] != with_strip[:, composer.view_w:]).any()


def test_cli_every_and_start_minute(tmp_path):
    out = tmp_path / "every.gif"
    rc = render.main(["--agent", "random", "--start-minute", "1430", "--minutes", "30",
                      "--every", "3", "--size", "320x240", "--out", str(out), "--no-progress"])
    assert rc == 0
    # The day ends at minute 1440: 10 steps recorded, a frame after every third -> 4 frames.
    _, frames = _gif(out)
    assert len(frames) == 4


def test_overlay_is_drawn_over_the_raw_render(env):
    sim = _advance(env, 25)
    comp = render.FrameComposer(sim, 320, 240)
    raw_view = comp.raw_view()
    frame = np.asarray(comp.compose(step_reward=1.0))
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    # The panel region holds the overlay, not the raw render of the same size.
    raw_full = render_frame(sim, 320, 240)
    panel = frame[:, comp.view_w:]
    assert np.abs(panel.astype(int) - raw_full[:, comp.view_w:].astype(int)).sum(axis=2).mean() > 30
    assert len(np.unique(panel.reshape(-1, 3), axis=0)) > 20  # text, bars, colours
    # The 3-D view is the raw render with labels on it: mostly the same pixels, some changed.
    view = frame[:, : comp.view_w]
    ground = (raw_view != 255).any(axis=2)  # the sky is recoloured
    changed = (view != raw_view).any(axis=2) & ground
    assert 0.002 < changed.mean() < 0.3


def test_labels_sit_on_the_vehicles(env):
    """The projection used for labels matches TinyRenderer's: each visible body's colour is
    at its projected centre."""
    sim = _advance(env, 3)
    comp = render.FrameComposer(sim, 400, 300)
    raw = comp.raw_view().astype(float)
    px = comp.camera.project(sim.pos)
    palette = np.array([c[:3] for c in VEHICLE_COLOURS[: sim.n]], dtype=float)
    palette /= np.linalg.norm(palette, axis=1, keepdims=True)
    checked = 0
    for v in range(sim.n):
        if sim.status[v] == AWAY:
            continue
        x, y = np.round(px[v]).astype(int)
        rgb = raw[y, x] / max(np.linalg.norm(raw[y, x]), 1e-9)
        sim_to = palette @ rgb
        assert int(np.argmax(sim_to)) == v and sim_to[v] > 0.97, (v, raw[y, x])
        checked += 1
    assert checked >= 2


def test_camera_fits_the_airspace(env):
    sim = _advance(env, 0)
    cam = render.fit_camera(sim, 400, 480)
    r = sim.layout.airspace_radius_m
    ang = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    ring = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)], axis=1)
    px = cam.project(ring)
    assert np.isfinite(px).all()
    assert px[:, 0].min() >= 0 and px[:, 0].max() <= 400
    assert px[:, 1].min() >= 0 and px[:, 1].max() <= 480
    assert px[:, 0].max() - px[:, 0].min() > 0.7 * 400  # and fills most of the view


def test_unknown_agent_exits_2_naming_it(tmp_path):
    out = tmp_path / "x.gif"
    proc = subprocess.run(
        [sys.executable, "-m", "agents.render", "--agent", "no_such_agent_xyz", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and "pybullet build time" not in ln]
    assert len(lines) == 1 and "no_such_agent_xyz" in lines[0], proc.stderr
    assert not out.exists()


def test_unwritable_output_is_a_clear_error(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    rc = render.main(["--agent", "random", "--minutes", "1", "--out", str(blocker / "x.gif"),
                      "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "cannot write output" in err and "x.gif" in err
    rc = render.main(["--agent", "random", "--out", str(tmp_path), "--no-progress"])
    assert rc == 2
    assert "use a .gif or .mp4" in capsys.readouterr().err


def test_mp4_without_a_writer_is_a_clear_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(render.cli, "_mp4_backend", lambda: None)
    rc = render.main(["--agent", "random", "--out", str(tmp_path / "x.mp4"), "--no-progress"])
    assert rc == 2
    assert ".mp4 needs imageio-ffmpeg or av" in capsys.readouterr().err


def test_bad_size_is_rejected(capsys):
    with pytest.raises(SystemExit) as exc:
        render.main(["--size", "640by480"])
    assert exc.value.code == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err


def test_help_documents_every_option(capsys):
    with pytest.raises(SystemExit):
        render.main(["--help"])
    text = capsys.readouterr().out
    for opt in ("--agent", "--config", "--seed", "--start-minute", "--minutes", "--every",
                "--fps", "--size", "--out"):
        assert opt in text


def test_hhmm():
    assert render.hhmm(0) == "00:00"
    assert render.hhmm(605.0) == "10:05"
    assert render.hhmm(1440) == "24:00"


def test_mp4_when_a_writer_is_installed(tmp_path):
    if render.video._mp4_backend() is None:
        pytest.skip("no MP4 writer (imageio-ffmpeg or av) installed")
    out = tmp_path / "x.mp4"
    assert render.main(["--agent", "random", "--minutes", "4", "--size", "320x240",
                        "--out", str(out), "--no-progress"]) == 0
    assert out.stat().st_size > 0


def test_outcome_words():
    from agents.render.panel import StatusPanel

    assert StatusPanel._outcomes({"action": 1, "takeoff": True, "good_takeoff": True})[0][0].endswith("take-off ok")
    words = [w for w, _ in StatusPanel._outcomes(
        {"action": 13, "commanded_action": 12, "conflict": True, "reward_terms": {"safety": -5.0}})]
    assert words == ["\u2717 conflict", "misread"]


def test_rendering_does_not_change_the_episode():
    """The recorded episode is the evaluated one: same seed, same steps, same metrics."""
    def run(with_frames):
        e = vertiport_v1.env(config="paper", render_mode="rgb_array")
        try:
            if with_frames:
                frames = render.record_episode(
                    e, RandomController(), 11, lambda s: render.FrameComposer(s, 320, 240),
                    start_step=20, n_steps=10, every=2, progress=False)
                assert len(frames) == 5
            else:
                e.reset(seed=11)
                policy = RandomController()
                policy.reset(seed=11)
                for _ in range(29):
                    e.step(policy.act(e.observe(e.agent_selection)))
            sim = e.unwrapped.sim
            return sim.step_count, sim.metrics.total_reward, sim.pos.copy(), sim.battery.copy()
        finally:
            e.close()

    a, b = run(True), run(False)
    assert a[0] == b[0] == 29
    assert a[1] == b[1]
    np.testing.assert_array_equal(a[2], b[2])
    np.testing.assert_array_equal(a[3], b[3])


def test_a_lost_vehicle_and_a_failed_charger_are_drawn(env):
    """A vehicle lost on the ground keeps its port, and the panel says it is lost; a charger
    that failed in the step is drawn as failed; the key explains the tags."""
    from agents.render.panel import StatusPanel
    from agents.render.style import RED
    from marl_vertiport.sim.layout import CHARGING_PORT

    sim = _advance(env, 25)
    comp = render.FrameComposer(sim, 640, 480)
    before = np.asarray(comp.compose(step_reward=0.0))
    sim.lost[0] = True
    text, colour = StatusPanel(comp)._schedule_text(0)
    assert "lost" in text and colour == RED
    charger = int(np.flatnonzero(sim.layout.node_type == CHARGING_PORT)[0])
    sim.last_failed_chargers = (charger,)
    after = np.asarray(comp.compose(step_reward=0.0))
    x, y = (int(round(c)) for c in comp._port_px[charger])
    near = (slice(max(0, y - 12), y + 12), slice(max(0, x - 14), x + 14))
    red = (np.abs(after[near].astype(int) - np.array(RED)).sum(axis=2) < 60).sum()
    red_before = (np.abs(before[near].astype(int) - np.array(RED)).sum(axis=2) < 60).sum()
    assert red > red_before + 10  # the ring and cross on the failed charger
    assert (after[:, comp.view_w:] != before[:, comp.view_w:]).any()  # the panel changed too
