"""One frame: the engine's image with each eVTOL labelled, and the side panel drawn with PIL
(time of day, the last ATC instruction, one row per eVTOL, running totals)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE, PENDING_LANDING,
    PENDING_TAKEOFF, TAXIING,
)
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT
from marl_vertiport.sim.physics import VEHICLE_COLOURS
from agents.render.camera import DEFAULT_PITCH_DEG, DEFAULT_YAW_DEG, fit_camera


LOW_BATTERY_PCT = 30.0

# Panel colours (RGB).
_BG = (28, 31, 38)
_ROW_BG = (38, 42, 51)
_ACT_BG = (58, 64, 80)
_TEXT = (235, 237, 242)
_DIM = (150, 156, 170)
_RED = (235, 70, 60)
_AMBER = (240, 175, 40)
_GREEN = (70, 190, 90)
_BLUE = (90, 160, 240)
_SKY = (214, 226, 238)
_STATUS_COLOUR = {
    ON_PORT: (200, 200, 205), ON_CHARGER: _GREEN, HOVERING: _AMBER, TAXIING: _BLUE,
    DEPARTING: (190, 140, 240), AWAY: _DIM, ARRIVING: (190, 140, 240), OUT_OF_SERVICE: _RED,
}
_STATUS_LABEL = {
    ON_PORT: "on port", ON_CHARGER: "charging", HOVERING: "hovering", TAXIING: "taxiing",
    DEPARTING: "departing", AWAY: "away", ARRIVING: "arriving", OUT_OF_SERVICE: "OUT OF SERVICE",
}



# ====================================================================== text helpers
def _font_dir() -> Path | None:
    try:
        import matplotlib

        return Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    except Exception:  # pragma: no cover - matplotlib is a dependency
        return None


def _font(size: int, bold: bool = False) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    size = max(6, int(round(size)))
    d = _font_dir()
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


def _rgb(rgba: tuple[float, ...]) -> tuple[int, int, int]:
    return tuple(int(round(255 * c)) for c in rgba[:3])  # type: ignore[return-value]


def _ink_on(rgb: tuple[int, int, int]) -> tuple[int, int, int]:
    """Black or white, whichever reads better on ``rgb``."""
    lum = 0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2]
    return (0, 0, 0) if lum > 140 else (255, 255, 255)


def _overlap(a: list[float], b: list[float]) -> float:
    """Area shared by two boxes ``[x0, y0, x1, y1]``."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _node_short(sim: VertiportSim, node: int) -> str:
    lay = sim.layout
    if node < lay.n_normal:
        return f"P{node}"
    if node < lay.n_ports:
        return f"C{node - lay.n_normal}"
    return f"H{node - lay.n_ports}"


def _node_long(sim: VertiportSim, node: int) -> str:
    kind = int(sim.layout.node_type[node])
    word = {CHARGING_PORT: "charger", HOVER_SPOT: "hover spot"}.get(kind, "port")
    return f"{word} {_node_short(sim, node)}"


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
        text = ("land on " if info.get("landing") else "go to ") + _node_long(sim, node)
    name = sim.actions.names(sim.layout)[a]
    return f"{text} [{name}]" if text.split()[0] in ("land", "go") else text


# ====================================================================== the frame
class FrameComposer:
    """Composes a frame: the 3-D view with labels on the left, the status panel on the right.

    Args:
        sim: the env's simulator (read only).
        width, height: size of the whole frame.
        yaw_deg, pitch_deg: camera angles (the distance is fitted to the airspace).
    """

    def __init__(self, sim: VertiportSim, width: int, height: int,
                 yaw_deg: float = DEFAULT_YAW_DEG, pitch_deg: float = DEFAULT_PITCH_DEG) -> None:
        self.sim = sim
        self.width, self.height = int(width), int(height)
        self.panel_w = max(120, int(round(self.width * 0.36)))
        self.view_w = self.width - self.panel_w
        self.camera = fit_camera(sim, self.view_w, self.height, yaw_deg, pitch_deg)
        self._matrix = self.camera.matrix
        self.colours = [_rgb(VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)]) for i in range(sim.n)]
        s = self.height / 480.0
        self.s = s
        self.f_clock = _font(max(10.0, 26 * s), bold=True)
        clock_h = self.f_clock.getbbox("00:00")[3] if hasattr(self.f_clock, "getbbox") else 26 * s
        pad = max(3, int(6 * s))
        # Header: clock, day bar, 3 lines; footer: 3 small lines; fleet rows share the rest,
        # 4 text lines per row (the body font shrinks for large fleets).
        body = 12.5 * s
        for _ in range(20):
            lh = math.ceil(body * 1.25)
            header_h = pad + clock_h + 2 * max(2, int(3 * s)) + max(2, int(4 * s)) + 3 * lh + pad
            footer_h = 3 * math.ceil(body * 0.88 * 1.25) + 2 * pad
            row_h = (self.height - header_h - footer_h) / max(sim.n, 1)
            if row_h >= 4.2 * lh or body <= 7.0:
                break
            body = max(7.0, body * 0.92)
        self.f_body = _font(body)
        self.f_bold = _font(body, bold=True)
        self.f_small = _font(max(6.0, body * 0.88))
        self.f_label = _font(max(7.0, 11 * s), bold=True)
        self.f_port = _font(max(6.0, 9 * s))
        self.line_h = int(math.ceil(body * 1.25))
        self.small_h = int(math.ceil(max(6.0, body * 0.88) * 1.25))
        self.header_h = int(math.ceil(header_h))
        self.footer_h = int(math.ceil(footer_h))
        self.pad = pad
        # Name tags of the ports (under the front edge of each pad) and hover spots (beside).
        lay = sim.layout
        anchors = []
        for xy, kind, z in zip(lay.node_xy_m, lay.node_type, lay.node_z_m):
            if kind == HOVER_SPOT:
                anchors.append([xy[0] + 0.5, xy[1], float(z) - 0.6])
            else:
                anchors.append([xy[0], xy[1] - 1.7, 0.0])
        self._port_px = self.camera.project(np.asarray(anchors), self._matrix)
        self._acting = -1

    # ------------------------------------------------------------------ public
    def raw_view(self) -> np.ndarray:
        """The 3-D view alone (no overlay), ``(height, view_w, 3)``."""
        return self.camera.image(self.sim)

    def compose(self, step_reward: float | None = None, view: np.ndarray | None = None) -> Image.Image:
        """The full frame for the simulator's current state, as an RGB PIL image."""
        view = self.raw_view() if view is None else view
        frame = Image.new("RGB", (self.width, self.height), _BG)
        view = np.array(view, copy=True)
        sky = (view[:, :, 0] == 255) & (view[:, :, 1] == 255) & (view[:, :, 2] == 255)  # clear colour
        view[sky] = _SKY
        frame.paste(Image.fromarray(view), (0, 0))
        draw = ImageDraw.Draw(frame)
        info = self.sim.last_info or {}
        self._acting = (int(str(info["acting_agent"]).rsplit("_", 1)[-1])
                        if "acting_agent" in info else -1)
        self._draw_scene_labels(draw)
        self._draw_panel(draw, step_reward)
        return frame

    # ------------------------------------------------------------------ 3-D view
    def _draw_scene_labels(self, d: ImageDraw.ImageDraw) -> None:
        sim, s = self.sim, self.s
        # Ports and hover spots: a short name next to each.
        for k, (x, y) in enumerate(self._port_px):
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            if sim.layout.node_type[k] == HOVER_SPOT:
                d.text((x + 2 * s, y), _node_short(sim, k), font=self.f_port, fill=(95, 85, 30),
                       anchor="lm")
            else:
                d.text((x, y + 1), _node_short(sim, k), font=self.f_port, fill=(40, 40, 50),
                       anchor="mt")
        self._draw_scene_key(d)
        pos = np.asarray(sim.pos, dtype=float)
        ground = pos.copy()
        ground[:, 2] = 0.0
        r = sim.layout.airspace_radius_m
        edge = np.zeros_like(pos)
        for v in range(sim.n):
            xy = pos[v, :2]
            norm = float(np.hypot(*xy)) or 1.0
            edge[v, :2] = xy / norm * r
        px = self.camera.project(np.concatenate([pos, ground, edge]), self._matrix)
        vpx, gpx, epx = px[: sim.n], px[sim.n: 2 * sim.n], px[2 * sim.n:]
        park_z = sim.park_z_m
        # Pairs that have lost separation: a red line between them.
        for a, b in sorted(getattr(sim, "sep_state", ())):
            if (sim.status[a] != AWAY and sim.status[b] != AWAY
                    and np.isfinite(vpx[[a, b]]).all()):
                d.line([tuple(vpx[a]), tuple(vpx[b])], fill=_RED, width=max(1, int(2 * s)))
        lw = max(1, int(round(2 * s)))
        placed: list[list[float]] = []
        tags = []
        for v in range(sim.n):
            col = self.colours[v]
            status = int(sim.status[v])
            if status == AWAY:
                box = self._draw_away_marker(d, v, epx[v], pos[v], placed)
                if box is not None:
                    placed.append(box)
                continue
            x, y = vpx[v]
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            alt = pos[v, 2]
            airborne = alt > park_z + 0.3
            if airborne:  # a dashed drop line to the ground shows the height
                gx, gy = gpx[v]
                self._dashed(d, (x, y), (gx, gy), fill=(70, 70, 80), width=1, dash=3 * s)
                rr = max(2, int(2.5 * s))
                d.ellipse([gx - rr, gy - rr * 0.6, gx + rr, gy + rr * 0.6], fill=(90, 90, 100))
            # A ring in the body colour makes the small bodies easy to find.
            rr = max(4.0, 9.0 * s)
            d.ellipse([x - rr, y - rr * 0.8, x + rr, y + rr * 0.8], outline=col, width=lw)
            if status == OUT_OF_SERVICE:
                c = 5 * s
                d.line([(x - c, y - c), (x + c, y + c)], fill=_RED, width=lw)
                d.line([(x - c, y + c), (x + c, y - c)], fill=_RED, width=lw)
            text = str(v) + (f" {alt:.0f}m" if airborne else "")
            if bool(sim.conflict[v]):
                text += " !"
            outline = (20, 20, 20)
            if status == OUT_OF_SERVICE or bool(sim.conflict[v]):
                outline = _RED
            if v == self._acting:
                outline = (255, 255, 255)
            tags.append((v, x, y, text, col, outline))
        # Tags: above-right of the body if free, else another corner, with a leader line.
        pad = max(1, int(2 * s))
        ox, oy = 8 * s, 14 * s
        corners = ((ox, -oy, "lb"), (-ox, -oy, "rb"), (ox, oy, "lt"), (-ox, oy, "rt"))
        for v, x, y, text, col, outline in tags:
            best = None
            for dx, dy, anchor in corners:
                bb = d.textbbox((x + dx, y + dy), text, font=self.f_label, anchor=anchor)
                box = [bb[0] - pad, bb[1] - pad, bb[2] + pad, bb[3] + pad]
                cost = sum(_overlap(box, other) for other in placed)
                cost += 1e6 * (box[0] < 0 or box[1] < 0 or box[2] > self.view_w
                               or box[3] > self.height)
                if best is None or cost < best[0]:
                    best = (cost, box, (x + dx, y + dy), anchor)
                if cost == 0:
                    break
            _, box, at, anchor = best
            placed.append(box)
            corner = (box[0] if anchor[0] == "l" else box[2], box[3] if anchor[1] == "b" else box[1])
            d.line([(x, y), corner], fill=(20, 20, 20), width=1)
            d.rectangle(box, fill=col, outline=outline, width=max(1, int(round(1.5 * s))))
            d.text(at, text, font=self.f_label, fill=_ink_on(col), anchor=anchor)

    def _draw_scene_key(self, d: ImageDraw.ImageDraw) -> None:
        """A small key of the ground markings in the bottom-left corner of the 3-D view."""
        s = self.s
        items = [((62, 62, 74), "P port"), ((30, 160, 65), "C charger"), ((235, 200, 50), "H hover spot"),
                 ((75, 75, 220), "airspace edge")]
        x, y = max(3, int(5 * s)), self.height - max(3, int(5 * s))
        step = int(math.ceil(self.f_port.size * 1.3)) if hasattr(self.f_port, "size") else 12
        r = max(2, int(3 * s))
        for colour, text in reversed(items):
            d.ellipse([x, y - step / 2 - r, x + 2 * r, y - step / 2 + r], fill=colour)
            d.text((x + 2 * r + 3, y - step / 2), text, font=self.f_port, fill=(50, 50, 60), anchor="lm")
            y -= step

    def _draw_away_marker(self, d: ImageDraw.ImageDraw, v: int, p: np.ndarray,
                          pos: np.ndarray, placed: list[list[float]]) -> list[float] | None:
        """A vehicle outside the airspace: a tag on the boundary in its direction, with its
        distance beyond the boundary. Returns the tag's box."""
        x, y = p
        if not (np.isfinite(x) and np.isfinite(y)):
            return None
        s, col = self.s, self.colours[v]
        dist = float(np.hypot(*pos[:2])) - self.sim.layout.airspace_radius_m
        text = f"{v} +{max(dist, 0):.0f}m"
        bb = d.textbbox((x, y), text, font=self.f_small, anchor="mm")
        pad = max(1, int(2 * s))
        w, h = bb[2] - bb[0] + 2 * pad, bb[3] - bb[1] + 2 * pad
        # Shift along y to clear other tags, then into the view.
        cx, cy = float(x), float(y)
        for k in range(8):
            box = [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]
            if not any(_overlap(box, o) for o in placed):
                break
            cy = y + (h + 1) * ((k // 2) + 1) * (1 if k % 2 == 0 else -1)
        cx = min(max(cx, w / 2 + 1), self.view_w - w / 2 - 1)
        cy = min(max(cy, h / 2 + 1), self.height - h / 2 - 1)
        box = [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]
        d.rectangle(box, fill=(245, 245, 245), outline=col, width=max(1, int(round(2 * s))))
        d.text((cx, cy), text, font=self.f_small, fill=(40, 40, 40), anchor="mm")
        return box

    @staticmethod
    def _dashed(d: ImageDraw.ImageDraw, a: tuple[float, float], b: tuple[float, float],
                fill: tuple[int, int, int], width: int = 1, dash: float = 3.0) -> None:
        length = math.dist(a, b)
        if not np.isfinite(length) or length < 1:
            return
        n = max(1, int(length / (2 * dash)))
        for k in range(n):
            t0, t1 = (2 * k) / (2 * n), (2 * k + 1) / (2 * n)
            d.line([(a[0] + (b[0] - a[0]) * t0, a[1] + (b[1] - a[1]) * t0),
                    (a[0] + (b[0] - a[0]) * t1, a[1] + (b[1] - a[1]) * t1)], fill=fill, width=width)

    # ------------------------------------------------------------------ panel
    def _schedule_text(self, v: int) -> tuple[str, tuple[int, int, int]]:
        sim = self.sim
        kind = int(sim.pending_kind[v])
        tol = sim.cfg.schedule.on_time_tolerance_min
        now = float(sim.minute)
        due = float(sim.pending_time[v])
        delay = float(sim.delay[v])
        if kind == PENDING_TAKEOFF:
            if delay > 0:
                return f"take-off delayed {delay:.0f} min", _RED
            if due - now > 0.5:
                colour = _TEXT if due - now > tol else _GREEN
                return f"take-off in {due - now:.0f} min ({hhmm(due)})", colour
            return f"take-off due now (by {hhmm(due + tol)})", _GREEN
        if kind == PENDING_LANDING:
            if delay > 0:
                return f"landing delayed {delay:.0f} min", _RED
            return f"land by {hhmm(due + tol)}", _AMBER if due + tol - now <= 5 else _TEXT
        status = int(sim.status[v])
        if status in (DEPARTING, AWAY):
            dest = int(sim.dest[v])
            back = " (returning)" if status == AWAY and bool(sim.returning[v]) else ""
            return f"trip to destination D{dest}{back}", _DIM
        if status == OUT_OF_SERVICE:
            return "battery depleted: grounded", _RED
        if status == TAXIING and sim.landing_cleared[v]:
            return "landing", _DIM
        return "no flight scheduled", _DIM

    def _draw_panel(self, d: ImageDraw.ImageDraw, step_reward: float | None) -> None:
        sim, s = self.sim, self.s
        x0 = self.view_w
        W = self.panel_w
        pad = max(3, int(6 * s))
        lh = self.line_h
        d.rectangle([x0, 0, self.width, self.height], fill=_BG)
        # ---- header: clock, day progress, last instruction
        day_min = sim.cfg.schedule.episode_steps * sim.minutes_per_step
        d.text((x0 + pad, pad), hhmm(sim.minute), font=self.f_clock, fill=_TEXT, anchor="lt")
        cb = d.textbbox((x0 + pad, pad), hhmm(sim.minute), font=self.f_clock, anchor="lt")
        d.text((cb[2] + pad, cb[3]), f"step {sim.step_count}", font=self.f_small, fill=_DIM,
               anchor="ld")
        bar_y = cb[3] + max(2, int(3 * s))
        bar_h = max(2, int(3 * s))
        d.rectangle([x0 + pad, bar_y, x0 + W - pad, bar_y + bar_h], fill=_ROW_BG)
        frac = min(1.0, float(sim.minute) / max(day_min, 1e-9))
        d.rectangle([x0 + pad, bar_y, x0 + pad + (W - 2 * pad) * frac, bar_y + bar_h], fill=_BLUE)
        y = bar_y + bar_h + max(2, int(4 * s))
        info = sim.last_info or {}
        acting = self._acting
        if "action" in info:
            col = self.colours[acting]
            sw = lh - 3
            d.rectangle([x0 + pad, y + 1, x0 + pad + sw, y + 1 + sw], fill=col)
            d.text((x0 + pad + sw + 4, y), f"ATC \u2192 eVTOL {acting} at {hhmm(info['minute'])}",
                   font=self.f_bold, fill=_TEXT)
            y += lh
            d.text((x0 + pad, y), self._fit(d, describe_action(sim, info), self.f_body,
                                            W - 2 * pad), font=self.f_body, fill=_TEXT)
            y += lh
            rtxt = f"reward {step_reward:+.2f}" if step_reward is not None else ""
            d.text((x0 + pad, y), rtxt, font=self.f_small, fill=_DIM)
            xr = x0 + W - pad
            for text, colour in reversed(self._outcomes(info)):
                d.text((xr, y), text, font=self.f_small, fill=colour, anchor="ra")
                xr = d.textbbox((xr, y), text, font=self.f_small, anchor="ra")[0] - 5
        else:
            d.text((x0 + pad, y), "start of the day", font=self.f_bold, fill=_DIM)
            y += 2 * lh
        # ---- fleet rows
        top = self.header_h
        bottom = self.height - self.footer_h
        row_h = (bottom - top) / max(sim.n, 1)
        for v in range(sim.n):
            self._draw_row(d, v, x0, int(top + v * row_h), int(row_h) - max(1, int(2 * s)), pad)
        # ---- totals
        m = sim.metrics
        y = bottom + pad
        lines = [
            (f"total reward {m.total_reward:+.1f}", _TEXT),
            (f"good take-offs {m.good_takeoffs}/{m.takeoffs} \u00b7 landings "
             f"{m.good_landings}/{m.landings}", _TEXT),
            (f"collisions {m.collisions} \u00b7 avoided {m.avoided_conflicts} \u00b7 sep. losses "
             f"{m.separation_losses}", _RED if m.collisions or m.separation_losses else _TEXT),
        ]
        sl = self.small_h
        for text, colour in lines:
            d.text((x0 + pad, y), self._fit(d, text, self.f_small, W - 2 * pad), font=self.f_small,
                   fill=colour)
            y += sl

    @staticmethod
    def _outcomes(info: dict) -> list[tuple[str, tuple[int, int, int]]]:
        """What the last instruction led to, as short coloured words."""
        out = []
        if info.get("takeoff"):
            good = bool(info.get("good_takeoff"))
            out.append(("\u2713 take-off ok" if good else "\u2717 bad take-off", _GREEN if good else _RED))
        elif info.get("takeoff_failed"):
            out.append(("\u2717 take-off failed", _RED))
        elif info.get("landing"):
            good = bool(info.get("good_landing"))
            out.append(("\u2713 landing ok" if good else "\u2717 bad landing", _GREEN if good else _RED))
        if info.get("conflict"):
            avoided = info.get("reward_terms", {}).get("safety", 0.0) > 0
            out.append(("\u2713 avoided" if avoided else "\u2717 conflict", _GREEN if avoided else _RED))
        if info.get("commanded_action", info.get("action")) != info.get("action"):
            out.append(("misread", _AMBER))
        return out

    def _draw_row(self, d: ImageDraw.ImageDraw, v: int, x0: int, y0: int, h: int, pad: int) -> None:
        sim, s, W, lh = self.sim, self.s, self.panel_w, self.line_h
        col = self.colours[v]
        status = int(sim.status[v])
        bg = _ACT_BG if v == self._acting else _ROW_BG
        d.rectangle([x0 + pad // 2, y0, x0 + W - pad // 2, y0 + h], fill=bg)
        d.rectangle([x0 + pad // 2, y0, x0 + pad // 2 + max(3, int(5 * s)), y0 + h], fill=col)
        x = x0 + pad + max(4, int(6 * s))
        right = x0 + W - pad
        y = y0 + max(1, int(2 * s))
        # line 1: name, status
        d.text((x, y), f"eVTOL {v}", font=self.f_bold, fill=col)
        nb = d.textbbox((x, y), f"eVTOL {v}", font=self.f_bold)
        where = ""
        node = int(sim.node[v])
        if node >= 0 and status in (ON_PORT, ON_CHARGER, HOVERING, OUT_OF_SERVICE):
            where = f" {_node_short(sim, node)}"
        elif node >= 0 and status in (TAXIING, ARRIVING):
            where = f" \u2192{_node_short(sim, node)}"
        d.text((right, y), _STATUS_LABEL[status] + where, font=self.f_body,
               fill=_STATUS_COLOUR[status], anchor="ra")
        if v == self._acting:
            d.text((nb[2] + 3, y), "\u25c0", font=self.f_body, fill=_TEXT)
        y += lh
        # line 2: battery bar and percent
        bat = float(sim.battery[v])
        bw = int((W - 2 * pad) * 0.5)
        bh = max(4, int(lh * 0.55))
        by = y + (lh - bh) // 2
        bcol = _RED if bat < LOW_BATTERY_PCT else (_AMBER if bat < 60 else _GREEN)
        d.rectangle([x, by, x + bw, by + bh], outline=_DIM, fill=(20, 22, 27))
        if bat > 0:
            d.rectangle([x + 1, by + 1, x + 1 + (bw - 2) * bat / 100.0, by + bh - 1], fill=bcol)
        thr_x = x + 1 + (bw - 2) * LOW_BATTERY_PCT / 100.0
        d.line([(thr_x, by - 1), (thr_x, by + bh + 1)], fill=_TEXT)
        d.text((x + bw + 4, y), f"{bat:3.0f} %", font=self.f_body,
               fill=_RED if bat < LOW_BATTERY_PCT else _TEXT)
        marks = []
        if status == ON_CHARGER:
            marks.append(("\u26a1", _GREEN))
        if bool(sim.conflict[v]):
            marks.append(("\u26a0 conflict", _RED))
        if sim.avoid_layer[v] >= 0:
            marks.append((f"\u2191{sim.cfg.flight.avoid_altitudes_m[int(sim.avoid_layer[v])]:.0f}m", _AMBER))
        mx = right
        for text, colour in reversed(marks):
            d.text((mx, y), text, font=self.f_body, fill=colour, anchor="ra")
            mx = d.textbbox((mx, y), text, font=self.f_body, anchor="ra")[0] - 4
        y += lh
        # line 3: schedule
        text, colour = self._schedule_text(v)
        d.text((x, y), self._fit(d, text, self.f_body, right - x), font=self.f_body, fill=colour)
        y += lh
        # line 4: delay totals / events of the last step
        extra = []
        info = sim.last_info or {}
        if int(str(info.get("acting_agent", "_-1")).rsplit("_", 1)[-1]) == v:
            if info.get("takeoff"):
                extra.append(("took off", _GREEN if info.get("good_takeoff") else _RED))
            if info.get("landing"):
                extra.append(("cleared to land", _GREEN if info.get("good_landing") else _RED))
        done = float(sim.completed_delay[v])
        if done > 0:
            extra.append((f"late so far {done:.0f} min", _DIM))
        if y + lh <= y0 + h + 2:
            xx = x
            for text, colour in extra:
                d.text((xx, y), text, font=self.f_small, fill=colour)
                xx = d.textbbox((xx, y), text, font=self.f_small)[2] + 8

    @staticmethod
    def _fit(d: ImageDraw.ImageDraw, text: str, font: Any, width: float) -> str:
        if d.textlength(text, font=font) <= width:
            return text
        while text and d.textlength(text + "\u2026", font=font) > width:
            text = text[:-1]
        return text + "\u2026"


