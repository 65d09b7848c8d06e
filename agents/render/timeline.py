"""A day at a glance: one figure of a whole day for an operator.

Four panels share the clock: each vehicle's battery; each vehicle's status as a band, with its
take-offs, landing clearances, failed take-offs, contacts and the moment it was lost; each
vehicle's delay; and the vertiport: charging ports in use, vehicles waiting in the air,
charger failures and wind gusts. The data come from a replay of the day through the episode
loop (:class:`TimelineRecorder` as an ``after_step`` hook), as the worst-day replay and
``render`` play it; for any day on demand::

    marl-vertiport timeline --agent dispatcher --config paper_uncertain --seed 1000000
    # runs/timeline/dispatcher_paper_uncertain_1000000.png
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.render.style import STATUS_COLOUR, STATUS_LABEL
from marl_vertiport.sim.layout import CHARGING_PORT
from marl_vertiport.sim.physics import VEHICLE_COLOURS
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER

__all__ = ["TimelineRecorder", "chain", "main", "timeline_png"]


def chain(*hooks: Callable | None) -> Callable:
    """One episode-loop hook that calls each of ``hooks`` (``None``s skipped) in turn."""
    live = [h for h in hooks if h is not None]

    def call(*args: Any) -> None:
        for hook in live:
            hook(*args)

    return call


class TimelineRecorder:
    """Records, after every step of a day, what :func:`timeline_png` draws (an ``after_step``
    hook of :func:`agents.controllers.episode.run_episode`)."""

    def __init__(self) -> None:
        self.minute: list[float] = []
        self.battery: list[np.ndarray] = []
        self.status: list[np.ndarray] = []
        self.delay: list[np.ndarray] = []
        self.lost: list[np.ndarray] = []
        self.charging: list[int] = []
        self.hovering: list[int] = []
        #: (minute, vehicle, kind) for take-offs (good or bad), landings, failed take-offs.
        self.events: list[tuple[float, int, str]] = []
        #: (minute, count) of the steps with contacts, charger failures and gusts.
        self.contacts: list[tuple[float, int]] = []
        self.charger_failures: list[tuple[float, int]] = []
        self.gusts: list[tuple[float, int]] = []
        self.chargers = 0

    def after_step(self, agent: str, action: int, env: Any) -> None:
        sim = env.unwrapped.sim
        info = sim.last_info or {}
        minute = float(sim.minute)
        self.chargers = int(np.count_nonzero(sim.layout.node_type == CHARGING_PORT))
        self.minute.append(minute)
        self.battery.append(np.array(sim.battery, dtype=float))
        self.status.append(np.array(sim.status, dtype=int))
        self.delay.append(np.array(sim.delay, dtype=float))
        self.lost.append(np.array(sim.lost, dtype=bool))
        self.charging.append(int(np.count_nonzero(sim.status == ON_CHARGER)))
        self.hovering.append(int(np.count_nonzero(sim.status == HOVERING)))
        v = int(str(info.get("acting_agent", "_-1")).rsplit("_", 1)[-1])
        if info.get("takeoff"):
            self.events.append((minute, v, "take-off" if info.get("good_takeoff") else "bad take-off"))
        elif info.get("takeoff_failed"):
            self.events.append((minute, v, "failed take-off"))
        elif info.get("landing"):
            self.events.append((minute, v, "landing clearance"))
        for key, store in (("contacts", self.contacts), ("charger_failures", self.charger_failures),
                           ("gusts", self.gusts)):
            if info.get(key):
                store.append((minute, int(info[key])))


def _rgb(colour: tuple[int, int, int]) -> tuple[float, float, float]:
    """A panel colour (0-255) as matplotlib's (0-1)."""
    return tuple(c / 255.0 for c in colour)


def timeline_png(rec: TimelineRecorder, title: str, agents: Sequence[str] = ()) -> bytes:
    """The day's figure (module docstring) as PNG bytes, carrying the provenance record of a
    run that played ``agents`` (:mod:`agents.common.provenance`)."""
    from agents.common.provenance import png_metadata, provenance

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not rec.minute:
        raise ValueError("the timeline has no step to draw")
    hours = np.asarray(rec.minute) / 60.0
    battery, status = np.stack(rec.battery), np.stack(rec.status)
    delay, lost = np.stack(rec.delay), np.stack(rec.lost)
    n = battery.shape[1]
    colours = [tuple(VEHICLE_COLOURS[v % len(VEHICLE_COLOURS)][:3]) for v in range(n)]
    fig, axes = plt.subplots(4, 1, figsize=(12, 3.6 + 1.4 + 0.28 * n + 2.6), sharex=True,
                             layout="constrained",
                             gridspec_kw={"height_ratios": [1.8, 0.6 + 0.25 * n, 1.0, 1.0]})
    ax_bat, ax_st, ax_del, ax_port = axes
    # Battery, with each loss marked where it happened.
    for v in range(n):
        ax_bat.plot(hours, battery[:, v], color=colours[v], lw=1.2, label=f"eVTOL {v}")
        first = np.flatnonzero(lost[:, v])
        if first.size:
            k = int(first[0])
            ax_bat.plot(hours[k], battery[k, v], "X", color="red", ms=11, mec="black")
    ax_bat.axhline(30, color="grey", lw=0.8, ls="--")
    ax_bat.set_ylabel("battery (%)")
    ax_bat.set_ylim(-3, 103)
    ax_bat.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    # Status bands, one row a vehicle, with the events of its turns.
    for v in range(n):
        runs = np.flatnonzero(np.diff(status[:, v])) + 1
        starts = np.concatenate([[0], runs])
        ends = np.concatenate([runs, [len(hours)]])
        dt = (hours[1] - hours[0]) if len(hours) > 1 else 1 / 60
        for a, b in zip(starts, ends):
            code = int(status[a, v])
            ax_st.broken_barh([(hours[a] - dt, hours[b - 1] - hours[a] + dt)], (v - 0.4, 0.8),
                              facecolors=_rgb(STATUS_COLOUR[code]))
        first = np.flatnonzero(lost[:, v])
        if first.size:
            ax_st.broken_barh([(hours[first[0]], hours[-1] - hours[first[0]] + dt)],
                              (v - 0.4, 0.8), facecolors="none", edgecolors="red", hatch="xx")
    style = {"take-off": ("^", "green"), "bad take-off": ("^", "red"),
             "landing clearance": ("v", "royalblue"), "failed take-off": ("x", "red")}
    for minute, v, kind in rec.events:
        marker, colour = style[kind]
        ax_st.plot(minute / 60.0, v, marker, color=colour, ms=5, mec="black", mew=0.4)
    for minute, count in rec.contacts:
        ax_st.plot(minute / 60.0, -0.7, "*", color="red", ms=12)
    ax_st.set_yticks(range(n), [f"eVTOL {v}" for v in range(n)], fontsize=8)
    ax_st.set_ylim(n - 0.5, -1.0)
    handles = [Patch(color=_rgb(STATUS_COLOUR[c]), label=STATUS_LABEL[c].lower())
               for c in sorted(STATUS_COLOUR)]
    handles += [Patch(facecolor="none", edgecolor="red", hatch="xx", label="lost")]
    handles += [Line2D([], [], marker=m, color=c, ls="", label=k) for k, (m, c) in style.items()]
    handles += [Line2D([], [], marker="*", color="red", ls="", ms=10, label="contact")]
    ax_st.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    # Delays.
    for v in range(n):
        ax_del.plot(hours, delay[:, v], color=colours[v], lw=1.0)
    ax_del.set_ylabel("delay (min)")
    # The vertiport: chargers in use, vehicles waiting aloft, failures and gusts.
    ax_port.step(hours, rec.charging, where="post", color="green", label="charging ports in use")
    ax_port.step(hours, rec.hovering, where="post", color="orange", label="vehicles hovering")
    top = max(1, rec.chargers, max(rec.hovering, default=0))
    if rec.charger_failures:
        f = np.asarray(rec.charger_failures, dtype=float)
        ax_port.plot(f[:, 0] / 60.0, np.full(len(f), top + 0.9), "|", color="red", ms=7,
                     label="charger failure")
    if rec.gusts:
        g = np.asarray(rec.gusts, dtype=float)
        ax_port.plot(g[:, 0] / 60.0, np.full(len(g), top + 0.5), "|", color="grey", ms=7,
                     label="wind gust")
    ax_port.set_ylim(-0.3, top + 1.3)
    ax_port.set_ylabel("vertiport")
    ax_port.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    ax_port.set_xlabel("time of day (h)")
    lost_n = int(lost[-1].sum())
    fig.suptitle(f"{title}: {lost_n} vehicle{'s' if lost_n != 1 else ''} lost, "
                 f"{sum(c for _, c in rec.contacts)} contacts, "
                 f"{sum(c for _, c in rec.charger_failures)} charger failures, "
                 f"{sum(1 for e in rec.events if e[2] == 'failed take-off')} failed take-offs")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata=png_metadata(provenance(agents)))
    plt.close(fig)
    return buf.getvalue()


def main(argv: Sequence[str] | None = None, prog: str = "python -m agents.render.timeline") -> int:
    from agents.controllers.episode import run_episode
    from agents.controllers.registry import AgentSpecError, agent_help, make_controller
    from agents.evaluate.episodes import versioned_env
    from agents.evaluate.settings import InputError, parse_overrides
    from marl_vertiport.config import LATEST_RULES, ConfigError

    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--agent", default="dispatcher", help=f"controller: {agent_help()}")
    parser.add_argument("--config", default="paper", help="env config name or YAML path")
    parser.add_argument("--seed", type=int, default=1_000_000, help="the day (default: the first test day)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="a config override (repeatable)")
    parser.add_argument("--rules", type=int, default=LATEST_RULES, help="the env's rules version")
    parser.add_argument("--out", type=Path, help="the PNG (default runs/timeline/AGENT_CONFIG_SEED.png)")
    args = parser.parse_args(argv)
    try:
        overrides = dict(parse_overrides(args.overrides))
        policy = make_controller(args.agent)
        env = versioned_env(args.config, overrides, args.rules)
    except (AgentSpecError, ConfigError, InputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rec = TimelineRecorder()
    try:
        run_episode(env, policy, args.seed, after_step=rec.after_step)
    finally:
        env.close()
    stem = f"{args.agent}_{Path(args.config).stem}_{args.seed}".replace(":", "_").replace("/", "_")
    out = args.out or Path("runs/timeline") / f"{stem}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out, timeline_png(rec, f"{args.agent} on {args.config}, day {args.seed}",
                                   [args.agent]))
    print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
