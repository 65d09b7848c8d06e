"""The worst-day replay of an evaluation: for each controller and case of a run, the day an
operator should watch first (:mod:`agents.evaluate.worst`: its first day with a vehicle lost or
a contact, else its lowest reward), played again and rendered with its decision log.

Usage::

    python -m agents.render.worst_day runs/eval                  # every agent x case of the run
    python -m agents.render.worst_day runs/eval --agents gcn --configs paper_uncertain

For each pick the day is played twice from the run's settings (config, overrides, rules, seed):
once whole, logging every turn (:class:`agents.controllers.decisions.DecisionLog`), which finds
the window to show (``--before-min`` minutes before the first loss or contact to
``--after-min`` after it; on a day without one, the ``--window-min`` minutes of lowest reward)
and checks that the replay earns the reward the run recorded; then again, rendered over that
window with each turn's decision on the frames. Writes into ``<run>/worst_day/``:
``<agent>_<config>.gif``, ``<agent>_<config>.decisions.csv`` and ``.json`` (the whole day's
log), ``<agent>_<config>.timeline.png`` (the day at a glance) and ``index.md``, a table of the
picks, why, the event's minute, the window and whether the replay matched. ``--no-video``
plays each day once and writes all but the video: every worst day's timeline in seconds.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.files import write_atomic
from agents.common.names import canonical_spec
from agents.controllers.decisions import DecisionLog
from agents.controllers.episode import run_episode
from agents.controllers.registry import make_controller
from agents.evaluate.episodes import versioned_env
from agents.evaluate.worst import WorstDay, worst_days
from agents.render.frames import FrameComposer
from agents.render.style import rgb
from agents.render.timeline import TimelineRecorder, chain, timeline_png
from agents.render.cli import parse_size
from agents.render.video import GifQuantiser, RenderError, record_episode, run_cli, write_video
from marl_vertiport.config import LATEST_RULES
from marl_vertiport.sim.physics import VEHICLE_COLOURS

PROG = "python -m agents.render.worst_day"
#: The events of a decision-log row that make a day's "first loss or contact".
LOSS_EVENTS = ("vehicle lost", "contact")


def event_step(rows: list[dict[str, Any]]) -> int | None:
    """The step of the first row whose events include a vehicle lost or a contact."""
    for row in rows:
        if any(e in row["events"] for e in LOSS_EVENTS):
            return int(row["step"])
    return None


def lowest_reward_window(rows: list[dict[str, Any]], steps: int) -> int:
    """The first step of the ``steps`` consecutive turns of lowest summed reward."""
    rewards = np.array([r["reward"] for r in rows], dtype=float)
    if len(rewards) <= steps:
        return 0
    sums = np.convolve(rewards, np.ones(steps), mode="valid")
    return int(np.argmin(sums))


def replay(pick: WorstDay, overrides: dict[str, Any], rules: int, out: Path, *,
           before_min: float, after_min: float, window_min: float, size: tuple[int, int],
           progress: bool, spec: str | None = None, video: bool = True) -> dict[str, Any]:
    """Play ``pick``'s day whole with its log and its timeline, then (``video``) render its
    window; the index's row. ``spec`` builds the controller (default: ``pick.agent``;
    :func:`rebuildable`)."""
    spec = pick.agent if spec is None else spec
    policy = make_controller(spec)
    env = versioned_env(pick.config, overrides, rules)
    log, timeline = DecisionLog(policy), TimelineRecorder()
    try:
        metrics = run_episode(env, policy, pick.seed, before_step=log.before_step,
                              after_step=chain(log.after_step, timeline.after_step))
        mps = env.unwrapped.sim.minutes_per_step
        total_steps = env.unwrapped.sim.cfg.schedule.episode_steps
    finally:
        env.close()
    matched = math.isclose(metrics["total_reward"], pick.total_reward, rel_tol=1e-9, abs_tol=1e-6)
    event = event_step(log.rows)
    if event is not None:
        start = max(0, event - int(round(before_min / mps)))
        n_steps = min(total_steps, event + int(round(after_min / mps)) + 1) - start
    else:
        n_steps = max(1, int(round(window_min / mps)))
        start = lowest_reward_window(log.rows, n_steps)
    stem = f"{pick.agent}_{pick.config}".replace(":", "_").replace("/", "_").replace(".", "_")
    gif = out / f"{stem}.gif"
    write_atomic(out / f"{stem}.timeline.png", timeline_png(
        timeline, f"{pick.agent} on {pick.config}, day {pick.seed} ({pick.reason})",
        [pick.agent]))
    log.write(out / f"{stem}.decisions", {
        "agent": pick.agent, "config": pick.config, "seed": pick.seed, "reason": pick.reason,
        "overrides": overrides, "rules": rules, "video": gif.name if video else None,
        "first_frame_step": start, "event_step": event})
    row = {"pick": pick, "event_minute": None if event is None else event * mps,
           "window": (start * mps, (start + n_steps) * mps), "matched": matched,
           "replayed_reward": metrics["total_reward"], "video": gif.name if video else None,
           "log": f"{stem}.decisions.csv", "timeline": f"{stem}.timeline.png"}
    if not video:
        return row
    env = versioned_env(pick.config, overrides, rules, render_mode="rgb_array")
    try:
        colours = [rgb(VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)])
                   for i in range(env.unwrapped.sim.n)]
        player = make_controller(spec)  # a fresh controller: the day played again
        frames = record_episode(
            env, player, pick.seed, lambda s: FrameComposer(s, size[0], size[1]), start,
            n_steps, 1, progress=progress, convert=GifQuantiser(colours),
            log=DecisionLog(player))
    finally:
        env.close()
    write_video(frames, gif, 8.0, colours)
    return row


def index_markdown(run: Path, rows: list[dict[str, Any]]) -> str:
    lines = ["# Worst days", "",
             f"Replayed from `{run / 'episodes.csv'}` and `results.json` by `{PROG}`: per "
             "controller and case, its "
             "first day with a vehicle lost or a contact, else its day of lowest reward "
             "(agents/evaluate/worst.py), rendered around the first loss or contact (else its "
             "window of lowest reward) with each turn's decision on the frames; the day's "
             "decision log beside each video (`.decisions.csv`, `.json`; the turns with a choice "
             "alone in `.decisions.choices.csv`) and the whole day at a glance "
             "(`.timeline.png`).", "",
             "| agent | config | day (seed) | why | event at minute | window (minutes) | reward | "
             "lost | contacts | replay matches the run | video | decision log | timeline |",
             "|---|---|---:|---|---:|---|---:|---:|---:|---|---|---|---|"]
    for r in rows:
        p = r["pick"]
        event = "" if r["event_minute"] is None else f"{r['event_minute']:g}"
        lines.append(f"| {p.agent} | {p.config} | {p.seed} | {p.reason} | {event} | "
                     f"{r['window'][0]:g}-{r['window'][1]:g} | {p.total_reward:.1f} | "
                     f"{p.vehicles_lost} | {p.contacts} | "
                     f"{'yes' if r['matched'] else 'NO: ' + format(r['replayed_reward'], '.1f')} | "
                     f"{'-' if r['video'] is None else '[%s](%s)' % (r['video'], r['video'])} | "
                     f"[{r['log']}]({r['log']}) | "
                     f"[{r['timeline']}]({r['timeline']}) |")
    return "\n".join(lines) + "\n"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=prog, description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, help="an evaluation's output folder (with results.json)")
    ap.add_argument("--agents", nargs="+", default=None, help="only these agents of the run")
    ap.add_argument("--configs", nargs="+", default=None, help="only these configs of the run")
    ap.add_argument("--before-min", type=float, default=90.0,
                    help="minutes shown before the first loss or contact (default: %(default)g)")
    ap.add_argument("--after-min", type=float, default=30.0,
                    help="minutes shown after it (default: %(default)g)")
    ap.add_argument("--window-min", type=float, default=120.0,
                    help="minutes shown of a day without a loss or contact (default: %(default)g)")
    ap.add_argument("--size", type=parse_size, default="640x480",
                    help="frame size WxH (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=None,
                    help="output folder (default: <run>/worst_day)")
    ap.add_argument("--no-video", action="store_true",
                    help="the timelines and decision logs only, no video (seconds a day for a "
                         "rule)")
    ap.add_argument("--no-progress", action="store_true")
    return ap


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    return run_cli(build_parser(prog), _run, argv)


def rebuildable(spec: str, record: dict[str, Any]) -> str:
    """``spec`` as it builds from here: itself where it does, else (an import path that does
    not resolve from this folder) the same class from the file the run's record names
    (``provenance.controllers``), if that file is still what the run played (its SHA-256)."""
    from agents.common.provenance import file_sha256
    from agents.common.specs import AgentSpecError, split_spec
    from agents.controllers.registry import make_controller

    try:
        make_controller(spec)
        return spec
    except AgentSpecError as exc:
        entry = (record.get("controllers") or {}).get(spec)
        if not entry:
            raise RenderError(f"{exc} (and the run's record names no file for it)") from None
        if "file" not in entry:
            raise RenderError(f"agent {spec!r} was an object in memory "
                              f"({entry.get('in_memory', 'unknown class')}); nothing rebuilds it "
                              "from the run's files") from None
    path = Path(entry["file"])
    if not path.is_file():
        raise RenderError(f"agent {spec!r}: not found from here, and the file the run played, "
                          f"{path}, is gone") from None
    if file_sha256(path) != entry["sha256"]:
        raise RenderError(f"agent {spec!r}: {path} changed since the run (SHA-256 "
                          f"{entry['sha256'][:16]} then): replaying it would not be the run")
    _, sep, args = spec.partition("[")
    target = split_spec(spec)[0]
    if ":" not in target:  # a policy file of another library: the file itself
        return f"{path}" + (f"[{args}" if sep else "")
    return f"{path}:{target.rpartition(':')[2]}" + (f"[{args}" if sep else "")


def _read_run(run: Path) -> tuple[dict[str, Any], list[dict[str, str]]]:
    """An evaluation's settings (``results.json``, with its provenance record) and its episodes
    (``episodes.csv``, which holds every scalar metric), agents named as now; a missing or
    broken file is a :class:`RenderError` naming it."""
    path = run / "results.json"
    try:
        doc = json.loads(path.read_text())
        settings = {**doc["settings"], "provenance": doc.get("provenance") or {}}
    except FileNotFoundError:
        raise RenderError(f"{path} not found: give an evaluation's output folder") from None
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise RenderError(f"{path} is not an evaluation's results.json ({exc})") from None
    path = run / "episodes.csv"
    try:
        with path.open(newline="") as fh:
            episodes = list(csv.DictReader(fh))
        for row in episodes:  # rows made before 0.2.0 name controllers by their old names
            row["agent"] = canonical_spec(row["agent"], note=False)
    except FileNotFoundError:
        raise RenderError(f"{path} not found: an evaluation writes it beside results.json") from None
    except (KeyError, TypeError, csv.Error, UnicodeDecodeError) as exc:
        raise RenderError(f"{path} is not an evaluation's episodes.csv ({exc})") from None
    return settings, episodes


def _run(args: argparse.Namespace) -> int:
    settings, episodes = _read_run(args.run)
    size = args.size
    picks = [w for w in worst_days(episodes)
             if (args.agents is None or w.agent in args.agents)
             and (args.configs is None or w.config in args.configs)]
    if not picks:
        raise RenderError(f"no day of {args.run} matches --agents {args.agents} --configs {args.configs}")
    out = args.out or args.run / "worst_day"
    overrides = dict(settings.get("overrides") or {})
    rules = int(settings.get("rules", LATEST_RULES))
    rows = []
    for k, pick in enumerate(picks, 1):
        print(f"[{k}/{len(picks)}] {pick.agent} on {pick.config}, day {pick.seed} "
              f"({pick.reason}) ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        row = replay(pick, overrides, rules, out, before_min=args.before_min,
                     after_min=args.after_min, window_min=args.window_min, size=size,
                     progress=not args.no_progress,
                     spec=rebuildable(pick.agent, settings["provenance"]),
                     video=not args.no_video)
        note = "" if row["matched"] else " (the replay's reward differs from the run's: another code or machine)"
        made = out / (row["video"] or row["timeline"])
        print(f"    wrote {made} and its decision log, {time.perf_counter() - t0:.0f} s{note}",
              file=sys.stderr)
        rows.append(row)
    write_atomic(out / "index.md", index_markdown(args.run, rows))
    print(f"wrote {out / 'index.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
