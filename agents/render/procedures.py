"""The airspace procedures of rules v1 as a figure (docs/separation_procedures.png): the
protected volumes the separation check (marl_vertiport/sim/clearance.py) reserves for a
departure, an arrival from a holding slot and a move between nodes, drawn from the simulator's
own volumes for the paper layout, in plan view and in a side view.

    python -m agents.render.procedures [--config paper] [--out docs/separation_procedures.png]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from agents.common.provenance import png_metadata, provenance
from marl_vertiport.config import load_config
from marl_vertiport.sim.clearance import volume
from marl_vertiport.sim.core import VertiportSim

OUT = Path(__file__).resolve().parents[2] / "docs" / "separation_procedures.png"


def _draw_segment(ax_plan, ax_side, seg, half_width_m: float, colour: str, label: str | None):
    """A segment of a volume in plan view (a band of ``half_width_m`` either side: where no
    other volume at its altitudes may come) and in the side view (distance from the centre
    against altitude)."""
    ax_, ay, bx, by, z0, z1 = seg
    dx, dy = bx - ax_, by - ay
    length = math.hypot(dx, dy)
    if length < 1e-9:
        ax_plan.add_patch(_circle(ax_, ay, half_width_m, colour))
        ax_plan.plot([ax_], [ay], "o", color=colour, ms=4, label=label)
        label = None
    else:
        nx, ny = -dy / length * half_width_m, dx / length * half_width_m
        ax_plan.fill([ax_ + nx, bx + nx, bx - nx, ax_ - nx], [ay + ny, by + ny, by - ny, ay - ny],
                     color=colour, alpha=0.18, lw=0)
        ax_plan.plot([ax_, bx], [ay, by], color=colour, lw=2, label=label)
        label = None
    r0, r1 = math.hypot(ax_, ay), math.hypot(bx, by)
    ax_side.plot([r0, r1] if length > 1e-9 else [r0, r0], [z0, z1] if length < 1e-9 else [z0, z0],
                 color=colour, lw=3, label=label)


def _circle(x: float, y: float, r: float, colour: str):
    from matplotlib.patches import Circle

    return Circle((x, y), r, color=colour, alpha=0.18, lw=0)


def figure(config: str, out: Path) -> Path:
    """Draw the procedures of ``config`` into ``out``; returns ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sim = VertiportSim(load_config(config))
    sim.reset(np.random.default_rng(0))
    lay, fl = sim.layout, sim.cfg.flight
    h_m, m_m = sim.clear_h_m, sim.margin_m
    fig, (plan, side) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1, 1.2]})
    theta = np.linspace(0, 2 * np.pi, 200)
    r = lay.airspace_radius_m
    plan.plot(r * np.cos(theta), r * np.sin(theta), color="0.6", lw=1, ls="--")
    for (x, y), kind in zip(lay.node_xy_m, lay.node_type):
        plan.plot(x, y, "s" if kind < 2 else "o", color=("0.2", "tab:green", "0.5")[kind], ms=8)
    plan.plot(sim.slot_pos[:, 0], sim.slot_pos[:, 1], "D", color="tab:purple", ms=7,
              label=f"holding slots ({fl.arrival_altitude_m:g} m)")
    departure = sim._trip_volume(0, 1)
    slot = 1
    spot = int(np.argmin(np.hypot(*(lay.node_xy_m - sim.slot_pos[slot, :2]).T)
                         + 1e9 * (lay.node_type != 2)))
    arrival = volume(sim.slot_pos[slot], sim._arrival_route(sim.slot_pos[slot], spot), m_m,
                     sim.park_z_m)
    taxi = sim._taxi_volume_list(lay.n_ports + 3)[2]
    for vol, colour, label in ((departure, "tab:red", f"departure ({fl.departure_altitude_m:g} m)"),
                               (arrival, "tab:blue", f"arrival ({fl.arrival_altitude_m:g} m)"),
                               (taxi, "tab:orange", f"move / landing ({fl.hover_altitude_m:g} m)")):
        for k, seg in enumerate(vol):
            _draw_segment(plan, side, seg, h_m / 2, colour, label if k == 0 else None)
    plan.set_aspect("equal")
    plan.set_xlim(-r - 3, r + 3)
    plan.set_ylim(-r - 3, r + 3)
    plan.set_title(f"plan view: protected volumes, bands {h_m / 2:g} m either side\n"
                   f"(two volumes at overlapping altitudes keep {h_m:g} m apart)")
    plan.legend(loc="lower left", fontsize=8)
    plan.set_xlabel("x (m)")
    plan.set_ylabel("y (m)")
    layers: dict[float, list[str]] = {}
    for alt, name in ((fl.hover_altitude_m, "moves"), (fl.departure_altitude_m, "departures"),
                      (fl.arrival_altitude_m, "arrivals, slots"),
                      *((a, "avoidance") for a in fl.avoid_altitudes_m)):
        layers.setdefault(alt, []).append(name)
    for alt, names in layers.items():
        side.axhline(alt, color="0.85", lw=1)
        side.text(r + 0.5, alt + 0.2, f"{alt:g} m: {', '.join(names)}", fontsize=8, color="0.4")
    side.axhline(sim.park_z_m, color="0.3", lw=1)
    side.set_xlim(0, r + 8)
    side.set_ylim(-0.5, max(fl.avoid_altitudes_m) + 3)
    side.set_xlabel("distance from the vertiport centre (m)")
    side.set_ylabel("altitude (m)")
    side.set_title(f"side view: climbs and descents extend {m_m:g} m behind their start;\n"
                   f"layers 4 m apart clear each other (vertical threshold {sim.clear_v_m:g} m)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + ".tmp.png")
    fig.savefig(tmp, dpi=100, metadata=png_metadata(provenance()))
    plt.close(fig)
    tmp.replace(out)
    sim.close()
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.render.procedures",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="paper", help="env config (default: paper)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"PNG to write (default: {OUT})")
    args = parser.parse_args(argv)
    print(figure(args.config, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
