"""Animated GIF (or MP4) of one episode of a controller, with a readable overlay.

Usage::

    python -m agents.render --agent dispatcher --config paper --out runs/render/dispatcher_paper.gif
    python -m agents.render --agent random --start-minute 360 --minutes 120 --every 2 --out x.gif

The controller runs through the AEC env exactly as in evaluation (``run_episode`` with the
same seed gives the same episode); the day is fast-forwarded to ``--start-minute`` without
rendering, then one frame is recorded after every ``--every``-th step for ``--minutes`` of the
day. Each frame is pybullet's TinyRenderer view of the airspace (camera chosen so the whole
airspace fits) with every eVTOL labelled by its index, and a side panel drawn with PIL: the
time of day, the last ATC instruction and its outcome, one row per eVTOL (battery, status,
schedule, events) and the running totals of the episode.

The decision log (:mod:`agents.controllers.decisions`) of every turn from the day's start to
the last frame is written beside the video (``<out>.decisions.csv`` and ``.json``), and a strip
over the 3-D view shows each frame's decision: the recommendation and who made it, the learned
policy's probabilities of the alternatives, and why the other actions are masked
(``--no-decisions``: neither).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path


from agents.common.files import write_atomic
from agents.common.seeds import EVAL_SEEDS
from agents.controllers.decisions import DecisionLog
from agents.controllers.registry import AgentSpecError, agent_help, make_controller
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.physics import VEHICLE_COLOURS
from agents.render.camera import DEFAULT_PITCH_DEG, DEFAULT_YAW_DEG
from agents.render.frames import FrameComposer
from agents.render.style import rgb
from agents.render.timeline import TimelineRecorder, timeline_png
from agents.render.video import (
    GifQuantiser, RenderError, _mp4_backend, record_episode, run_cli, write_video,
)


DEFAULT_SIZE = (640, 480)


# ====================================================================== CLI
def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)``."""
    try:
        w, h = (int(t) for t in text.lower().replace("\u00d7", "x").split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    if not (160 <= w <= 4096 and 120 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"size {text!r}: width 160..4096, height 120..4096")
    return w, h


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return v


def _non_negative_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number >= 0")
    return v


def _positive_float(text: str) -> float:
    v = _non_negative_float(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
    return v


PROG = "python -m agents.render"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=prog,
        description="Render part of one episode of a controller as an animated GIF (or MP4): "
                    "the 3-D vertiport with labelled eVTOLs, the time of day, the last ATC "
                    "instruction, and per eVTOL its battery, status, schedule and events.",
    )
    ap.add_argument("--agent", default="random",
                    help=f"controller: {agent_help()} (default: %(default)s)")
    ap.add_argument("--config", default="paper",
                    help="env config: a name in configs/env/ (paper, paper_uncertain) or a YAML "
                         "path (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=EVAL_SEEDS[0],
                    help="episode seed (default: %(default)s, the first evaluation seed, so the "
                         "video shows evaluation episode 0)")
    ap.add_argument("--start-minute", type=_non_negative_float, default=0.0, metavar="MIN",
                    help="minute of the day to start recording at; the day runs to there "
                         "without rendering (default: %(default)g)")
    ap.add_argument("--minutes", type=_positive_float, default=180.0, metavar="MIN",
                    help="minutes of the day to record, one step each in the shipped configs "
                         "(default: %(default)g, three hours)")
    ap.add_argument("--every", type=_positive_int, default=1, metavar="K",
                    help="record a frame after every K-th step (default: %(default)s)")
    ap.add_argument("--fps", type=_positive_float, default=8.0,
                    help="frames per second of the output (default: %(default)g)")
    ap.add_argument("--size", type=parse_size, default="x".join(map(str, DEFAULT_SIZE)),
                    metavar="WxH",
                    help="frame size in pixels; the 3-D view takes the left 64%%, the status "
                         "panel the rest (default: %(default)s)")
    ap.add_argument("--yaw", type=float, default=DEFAULT_YAW_DEG, metavar="DEG",
                    help="camera yaw; 0 puts +x to the right and +y away from the viewer "
                         "(default: %(default)g)")
    ap.add_argument("--pitch", type=float, default=DEFAULT_PITCH_DEG, metavar="DEG",
                    help="camera pitch; -90 looks straight down (default: %(default)g); the "
                         "distance is fitted so the whole airspace is in view")
    ap.add_argument("--out", type=Path, default=None, metavar="PATH",
                    help="output file, .gif, or .mp4 if imageio-ffmpeg or av is installed; "
                         "written atomically (default: runs/render/<agent>_<config>.gif)")
    ap.add_argument("--no-progress", action="store_true",
                    help="no progress bar on stderr while rendering")
    ap.add_argument("--no-decisions", action="store_true",
                    help="no decision strip on the frames and no decision log beside the video "
                         "(by default <out>.decisions.csv and .json: every turn's "
                         "recommendation, alternatives with probabilities, masked actions and "
                         "why)")
    return ap


def _check_output(out: Path) -> None:
    """Fail early, before the episode runs, on an output that cannot be written."""
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise RenderError(f"output {str(out)!r}: use a .gif or .mp4 file name")
    if suffix == ".mp4" and _mp4_backend() is None:
        raise RenderError(f"output {str(out)!r}: writing .mp4 needs imageio-ffmpeg or av "
                          "(pip install 'imageio[ffmpeg]'); or write a .gif")
    if out.is_dir():
        raise RenderError(f"output {str(out)!r} is a directory; give a file name")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=".probe", dir=out.parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise RenderError(f"cannot write output {str(out)!r}: {reason} "
                          f"(folder {str(out.parent)!r})") from None
    if out.exists() and not os.access(out, os.W_OK):
        raise RenderError(f"cannot write output {str(out)!r}: the file is read-only")


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    return run_cli(build_parser(prog), _run, argv)


def _run(args: argparse.Namespace) -> int:
    from marl_vertiport import vertiport_v1
    from marl_vertiport.config import ConfigError

    out = args.out or Path("runs/render") / f"{args.agent.replace(':', '_').replace('.', '_')}_{Path(str(args.config)).stem}.gif"
    try:
        policy = make_controller(args.agent)
    except AgentSpecError as exc:
        raise RenderError(str(exc)) from None
    _check_output(out)
    try:
        env = vertiport_v1.env(config=args.config, render_mode="rgb_array")
    except ConfigError as exc:
        raise RenderError(str(exc)) from None
    try:
        sim = env.unwrapped.sim
        mps = sim.minutes_per_step
        total_steps = sim.cfg.schedule.episode_steps
        start_step = int(math.ceil(args.start_minute / mps - 1e-9))
        if start_step >= total_steps:
            raise RenderError(f"--start-minute {args.start_minute:g} is past the end of the day "
                              f"({total_steps * mps:g} minutes)")
        n_steps = max(1, int(round(args.minutes / mps)))
        if start_step + n_steps > total_steps:
            n_steps = total_steps - start_step
            print(f"note: the day ends at minute {total_steps * mps:g}; recording "
                  f"{n_steps * mps:g} minutes", file=sys.stderr)
        width, height = args.size

        def factory(s: VertiportSim) -> FrameComposer:
            return FrameComposer(s, width, height, args.yaw, args.pitch)

        colours = [rgb(VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)]) for i in range(sim.n)]
        convert = GifQuantiser(colours) if out.suffix.lower() == ".gif" else None
        log = None if args.no_decisions else DecisionLog(policy)
        timeline = TimelineRecorder()
        t0 = time.perf_counter()
        frames = record_episode(env, policy, args.seed, factory, start_step, n_steps, args.every,
                                progress=not args.no_progress, convert=convert, log=log,
                                after_step=timeline.after_step)
    finally:
        env.close()
    write_video(frames, out, args.fps, colours)
    size_mb = out.stat().st_size / 1e6
    print(f"wrote {out} ({len(frames)} frames, {width}x{height}, {size_mb:.1f} MB, "
          f"{time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    if log is not None:
        paths = log.write(decision_log_stem(out), {
            "agent": args.agent, "config": str(args.config), "seed": args.seed,
            "video": out.name, "first_frame_step": start_step})
        print(f"wrote {paths[0]}, {paths[1].name} and {paths[2].name} ({len(log.rows)} turns, "
              f"{len(log.choices())} with a choice)", file=sys.stderr)
    png = out.with_name(out.stem + ".timeline.png")
    write_atomic(png, timeline_png(timeline, f"{args.agent} on {args.config}, day {args.seed}, "
                                             f"to minute {timeline.minute[-1]:.0f}", [args.agent]))
    print(f"wrote {png}", file=sys.stderr)
    return 0


def decision_log_stem(video: Path) -> Path:
    """Where a video's decision log goes: ``x.gif`` -> ``x.decisions`` (``.csv``, ``.json``)."""
    return video.with_name(video.stem + ".decisions")

