"""A day at a glance: the timeline recorder keeps every step of the day, marks what the
operator must see (losses, failures, gusts, the vehicles' turns), and the figure and its command
come out whole; render and the worst-day replay write it beside their videos."""

import numpy as np
from PIL import Image

from agents.controllers.episode import run_episode
from agents.controllers.registry import make_controller
from agents.render import timeline
from agents.render.timeline import TimelineRecorder, chain, timeline_png
from marl_vertiport import vertiport_v1


def _day(agent="random", config="paper_uncertain_10", steps=240, seed=1000000):
    env = vertiport_v1.env(config=config, **{"schedule.episode_steps": steps})
    rec, calls = TimelineRecorder(), []
    metrics = run_episode(env, make_controller(agent), seed,
                          after_step=chain(rec.after_step, lambda *a: calls.append(a[0]), None))
    env.close()
    return rec, metrics, calls


def test_the_recorder_keeps_every_step_and_the_events_of_the_day():
    rec, metrics, calls = _day()
    assert len(rec.minute) == metrics["steps"] == len(calls)  # chain called both hooks
    assert np.stack(rec.battery).shape == (metrics["steps"], 4)
    assert int(np.stack(rec.lost)[-1].sum()) == metrics["stranded"]
    assert sum(c for _, c in rec.charger_failures) > 0 and sum(c for _, c in rec.gusts) > 0
    kinds = {kind for _, _, kind in rec.events}
    assert kinds & {"take-off", "bad take-off"} and "failed take-off" in kinds
    takeoffs = sum(1 for e in rec.events if e[2] in ("take-off", "bad take-off"))
    assert takeoffs == metrics["takeoffs"]


def test_the_figure_and_its_command_come_out_whole(tmp_path):
    rec, metrics, _ = _day(steps=120)
    png = timeline_png(rec, "random on paper_uncertain_10")
    path = tmp_path / "day.png"
    path.write_bytes(png)
    image = Image.open(path)
    assert image.format == "PNG" and image.size[0] > 800 and image.size[1] > 500
    out = tmp_path / "cmd.png"
    assert timeline.main(["--agent", "fcfs", "--config", "paper", "--set",
                          "schedule.episode_steps=60", "--out", str(out)]) == 0
    assert Image.open(out).format == "PNG"
    assert timeline.main(["--agent", "no_such_agent", "--out", str(out)]) == 2


def test_the_figure_records_where_it_came_from(tmp_path):
    from agents.common.provenance import read_png_metadata

    rec, _, _ = _day(steps=30)
    path = tmp_path / "day.png"
    path.write_bytes(timeline_png(rec, "random", ["gcn"]))
    record = read_png_metadata(path)
    assert record["code"]["commit"] and "gcn" in record["checkpoints"]
