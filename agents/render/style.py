"""How a frame looks: the panel's colours, the status colours and labels, the fonts (DejaVu from
matplotlib's data, else Pillow's default), times of day, and names of nodes and instructions."""

from __future__ import annotations

import math
from pathlib import Path

from PIL import ImageFont

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE, TAXIING,
)

LOW_BATTERY_PCT = 30.0

# Panel colours (RGB).
BG = (28, 31, 38)
ROW_BG = (38, 42, 51)
ACT_BG = (58, 64, 80)
TEXT = (235, 237, 242)
DIM = (150, 156, 170)
RED = (235, 70, 60)
AMBER = (240, 175, 40)
GREEN = (70, 190, 90)
BLUE = (90, 160, 240)
SKY = (214, 226, 238)
STATUS_COLOUR = {
    ON_PORT: (200, 200, 205), ON_CHARGER: GREEN, HOVERING: AMBER, TAXIING: BLUE,
    DEPARTING: (190, 140, 240), AWAY: DIM, ARRIVING: (190, 140, 240), OUT_OF_SERVICE: RED,
}
STATUS_LABEL = {
    ON_PORT: "on port", ON_CHARGER: "charging", HOVERING: "hovering", TAXIING: "taxiing",
    DEPARTING: "departing", AWAY: "away", ARRIVING: "arriving", OUT_OF_SERVICE: "OUT OF SERVICE",
}



# ====================================================================== text helpers
def font_dir() -> Path | None:
    try:
        import matplotlib

        return Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    except Exception:  # pragma: no cover - matplotlib is a dependency
        return None


def font(size: int, bold: bool = False) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    size = max(6, int(round(size)))
    d = font_dir()
    if d is not None:
        path = d / ("DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf")
        try:
            return ImageFont.truetype(str(path), size)
        except OSError:
            pass
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - Pillow < 10.1
        return ImageFont.load_default()


def hhmm(minute: float) -> str:
    """Schedule minute as a time of day, ``HH:MM`` (the day runs from 00:00 to 24:00)."""
    m = int(math.floor(minute + 1e-9))
    return f"{m // 60:02d}:{m % 60:02d}"


def rgb(rgba: tuple[float, ...]) -> tuple[int, int, int]:
    return tuple(int(round(255 * c)) for c in rgba[:3])  # type: ignore[return-value]


def ink_on(rgb: tuple[int, int, int]) -> tuple[int, int, int]:
    """Black or white, whichever reads better on ``rgb``."""
    lum = 0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2]
    return (0, 0, 0) if lum > 140 else (255, 255, 255)


def overlap(a: list[float], b: list[float]) -> float:
    """Area shared by two boxes ``[x0, y0, x1, y1]``."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def node_short(sim: VertiportSim, node: int) -> str:
    lay = sim.layout
    if node < lay.n_normal:
        return f"P{node}"
    if node < lay.n_ports:
        return f"C{node - lay.n_normal}"
    return f"H{node - lay.n_ports}"


def short_action(name: str) -> str:
    """An action's name as the decision strip shows it: ``normal_port_0`` -> ``P0``,
    ``charging_port_1`` -> ``C1``, ``hover_spot_3`` -> ``H3``, the others as they are."""
    for prefix, short in (("normal_port_", "P"), ("charging_port_", "C"), ("hover_spot_", "H")):
        if name.startswith(prefix):
            return short + name[len(prefix):]
    return {"avoid_collision": "avoid"}.get(name, name)


def node_long(sim: VertiportSim, node: int) -> str:
    kind = int(sim.layout.node_type[node])
    word = {CHARGING_PORT: "charger", HOVER_SPOT: "hover spot"}.get(kind, "port")
    return f"{word} {node_short(sim, node)}"


def describe_action(sim: VertiportSim, info: dict) -> str:
    """The instruction of the last step in words, e.g. ``land on charger C0``."""
    a = int(info["action"])
    acts = sim.actions
    if a == acts.stay:
        text = "stay"
    elif a == acts.takeoff:
        text = "take off"
    elif a == acts.continue_:
        text = "continue"
    elif a == acts.avoid:
        text = "avoid collision"
    else:
        node = a - 2
        text = ("land on " if info.get("landing") else "go to ") + node_long(sim, node)
    name = sim.actions.names(sim.layout)[a]
    return f"{text} [{name}]" if text.split()[0] in ("land", "go") else text
