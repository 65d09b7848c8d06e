"""Animated GIF (or MP4) of one episode of a controller, with a readable overlay.

Usage::

    python -m agents.render --agent heuristic --config paper --out runs/render/heuristic_paper.gif
    python -m agents.render --agent random --start-minute 360 --minutes 120 --every 2 --out x.gif

The controller runs through the AEC env exactly as in evaluation (``run_aec_episode`` with the
same seed gives the same episode); the day is fast-forwarded to ``--start-minute`` without
rendering, then one frame is recorded after every ``--every``-th step for ``--minutes`` of the
day. Each frame is pybullet's TinyRenderer view of the airspace (camera chosen so the whole
airspace fits) with every eVTOL labelled by its index, and a side panel drawn with PIL: the
time of day, the last ATC instruction and its outcome, one row per eVTOL (battery, status,
schedule, events) and the running totals of the episode.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from agents.base import run_aec_episode
from agents.registry import BUILTIN, AgentSpecError, make_controller
from agents.seeds import EVAL_SEEDS
from marl_vertiport.sim.core import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE, PENDING_LANDING,
    PENDING_TAKEOFF, TAXIING, VertiportSim,
)
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT
# Labels are placed with the same projection the engine's camera uses.
from marl_vertiport.sim.physics import (
    CAMERA_FAR_M, CAMERA_FOV_DEG, CAMERA_NEAR_M, VEHICLE_COLOURS,
)

__all__ = ["Camera", "FrameComposer", "GifQuantiser", "fit_camera", "hhmm", "main", "parse_size",
           "record_episode", "write_video"]

DEFAULT_SIZE = (640, 480)
DEFAULT_YAW_DEG, DEFAULT_PITCH_DEG = 0.0, -65.0  # +x to the right, +y away from the viewer
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


class RenderError(Exception):
    """A user error the CLI reports in one line (exit status 2)."""


# ====================================================================== camera
def _gl_matrix(values: Any) -> np.ndarray:
    """pybullet's 16 floats (column-major, OpenGL) as a row-major 4x4 array."""
    return np.asarray(values, dtype=float).reshape(4, 4).T


@dataclass(frozen=True)
class Camera:
    """A TinyRenderer camera and the projection of world points to its pixels."""

    width: int
    height: int
    target_m: tuple[float, float, float]
    distance_m: float
    yaw_deg: float
    pitch_deg: float

    @property
    def matrix(self) -> np.ndarray:
        """Projection @ view, 4x4, as ``computeViewMatrixFromYawPitchRoll`` and
        ``computeProjectionMatrixFOV`` build them (they are pure functions of their inputs)."""
        import pybullet as p

        view = p.computeViewMatrixFromYawPitchRoll(list(self.target_m), self.distance_m,
                                                   self.yaw_deg, self.pitch_deg, 0, 2)
        proj = p.computeProjectionMatrixFOV(CAMERA_FOV_DEG, self.width / self.height,
                                            CAMERA_NEAR_M, CAMERA_FAR_M)
        return _gl_matrix(proj) @ _gl_matrix(view)

    def project(self, points_m: np.ndarray, matrix: np.ndarray | None = None) -> np.ndarray:
        """Pixel coordinates ``(N, 2)`` (x right, y down) of world points ``(N, 3)``; NaN for
        points behind the camera."""
        pts = np.atleast_2d(np.asarray(points_m, dtype=float))
        m = self.matrix if matrix is None else matrix
        clip = np.concatenate([pts, np.ones((len(pts), 1))], axis=1) @ m.T
        w = clip[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / w[:, None]
        ndc[w <= 1e-9] = np.nan
        return np.stack([(ndc[:, 0] + 1.0) * 0.5 * self.width,
                         (1.0 - ndc[:, 1]) * 0.5 * self.height], axis=1)

    def image(self, sim: VertiportSim) -> np.ndarray:
        """The raw RGB frame, ``(height, width, 3)`` uint8."""
        from marl_vertiport.render import draw_scenery

        draw_scenery(sim)
        return sim.physics.camera_image(self.width, self.height, self.target_m, self.distance_m,
                                        self.yaw_deg, self.pitch_deg)


def fit_camera(sim: VertiportSim, width: int, height: int, yaw_deg: float = DEFAULT_YAW_DEG,
               pitch_deg: float = DEFAULT_PITCH_DEG, margin: float = 0.04) -> Camera:
    """The closest camera at ``yaw``/``pitch`` whose view holds the whole airspace: its ground
    ring and the ring at the transit altitude, inside ``margin`` of each edge. The target is
    moved so the airspace sits in the middle of the picture."""
    lay, fl = sim.layout, sim.cfg.flight
    r = lay.airspace_radius_m * 1.03
    ang = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    ring = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)], axis=1)
    top = ring.copy()
    top[:, 2] = fl.transit_altitude_m
    pts = np.concatenate([ring, top])
    target = (0.0, 0.0, 0.0)

    def fits(dist: float, tgt: tuple[float, float, float]) -> bool:
        px = Camera(width, height, tgt, dist, yaw_deg, pitch_deg).project(pts)
        if np.isnan(px).any():
            return False
        return bool(px[:, 0].min() >= margin * width and px[:, 0].max() <= (1 - margin) * width
                    and px[:, 1].min() >= margin * height
                    and px[:, 1].max() <= (1 - margin) * height)

    for _ in range(3):  # fit the distance, then re-centre the picture on the airspace
        lo, hi = 1.0, 2000.0
        for _ in range(40):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if fits(mid, target) else (mid, hi)
        cam = Camera(width, height, target, hi, yaw_deg, pitch_deg)
        px = cam.project(pts)
        centre = np.array([(px[:, 0].min() + px[:, 0].max()) / 2, (px[:, 1].min() + px[:, 1].max()) / 2])
        off = centre - np.array([width / 2, height / 2])
        if np.abs(off).max() < 1.0:
            break
        # Move the target on the ground plane by the offset, measured in metres near the centre.
        o = cam.project(np.array([[target[0], target[1], 0.0], [target[0] + 1, target[1], 0.0],
                                  [target[0], target[1] + 1, 0.0]]))
        jac = np.stack([o[1] - o[0], o[2] - o[0]], axis=1)  # pixels per metre of x and y
        try:
            dxy = np.linalg.solve(jac, off)
        except np.linalg.LinAlgError:
            break
        target = (target[0] + float(dxy[0]), target[1] + float(dxy[1]), 0.0)
    return Camera(width, height, target, hi, yaw_deg, pitch_deg)


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


# ====================================================================== recording
class _Done(Exception):
    """Raised from the step callback once the last frame is recorded."""


def record_episode(env: Any, policy: Any, seed: int, composer_factory: Callable[[VertiportSim], FrameComposer],
                   start_step: int, n_steps: int, every: int, progress: bool = True,
                   convert: Callable[[Image.Image], Any] | None = None) -> list[Any]:
    """Run the episode with ``run_aec_episode`` (as evaluation does), fast-forward
    ``start_step`` steps without rendering, then compose a frame after every ``every``-th of
    the next ``n_steps`` steps; the episode stops after the last frame.

    Args:
        composer_factory: builds the :class:`FrameComposer` from the simulator.
        convert: applied to each RGB frame as it is made (e.g. a :class:`GifQuantiser`, so
            long recordings keep 1 byte per pixel in memory).

    Returns:
        The frames, RGB PIL images (or what ``convert`` made of them).
    """
    frames: list[Any] = []
    n_frames = len(range(0, n_steps, every))
    state: dict[str, Any] = {"composer": None, "bar": None}
    last = start_step + (n_frames - 1) * every

    def on_step(agent: str, action: int, env_: Any) -> None:
        sim = env_.unwrapped.sim
        k = sim.step_count - 1  # index of the step just taken
        if k < start_step or (k - start_step) % every:
            return
        if state["composer"] is None:
            state["composer"] = composer_factory(sim)
            if progress:
                from tqdm import tqdm

                state["bar"] = tqdm(total=n_frames, unit="frame", desc="rendering",
                                    file=sys.stderr, leave=True)
        reward = float(env_.rewards.get(agent, 0.0)) if hasattr(env_, "rewards") else None
        frame = state["composer"].compose(step_reward=reward)
        frames.append(convert(frame) if convert is not None else frame)
        if state["bar"] is not None:
            state["bar"].update(1)
        if k >= last:
            raise _Done

    try:
        run_aec_episode(env, policy, seed, on_step=on_step)
    except _Done:
        pass
    finally:
        if state["bar"] is not None:
            state["bar"].close()
    return frames


# ====================================================================== writing
def _mp4_backend() -> str | None:
    """``"ffmpeg"`` (imageio-ffmpeg) or ``"pyav"`` if imageio can write MP4 here, else ``None``."""
    for module, name in (("imageio_ffmpeg", "ffmpeg"), ("av", "pyav")):
        try:
            __import__(module)
        except ImportError:
            continue
        return name
    return None


class GifQuantiser:
    """Maps RGB frames to one 256-colour palette shared by the whole animation (no flicker
    between frames, and runs of equal pixels compress well). The palette comes from the first
    frame plus shades of every body and overlay colour, so colours that appear later (a red
    delay, a vehicle coming back) have an entry. No dithering: flat colours stay flat."""

    def __init__(self, colours: list[tuple[int, int, int]] | None = None) -> None:
        self.colours = list(colours or [])
        self.palette: Image.Image | None = None

    def _build(self, first: Image.Image) -> Image.Image:
        w, h = first.size
        extra = self.colours + [_BG, _ROW_BG, _ACT_BG, _TEXT, _DIM, _RED, _AMBER, _GREEN, _BLUE,
                                _SKY, (255, 255, 255), (0, 0, 0), (245, 245, 245)]
        shades = [tuple(int(v * f) for v in c) for c in extra for f in np.linspace(0.35, 1.0, 8)]
        strip = np.zeros((max(8, h // 4), w, 3), dtype=np.uint8)
        for k, c in enumerate(shades):
            strip[:, k * w // len(shades):(k + 1) * w // len(shades)] = c
        mosaic = Image.new("RGB", (w, h + strip.shape[0]))
        mosaic.paste(first, (0, 0))
        mosaic.paste(Image.fromarray(strip), (0, h))
        return mosaic.quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                               dither=Image.Dither.NONE)

    def __call__(self, frame: Image.Image) -> Image.Image:
        if self.palette is None:
            self.palette = self._build(frame)
        return frame.quantize(palette=self.palette, dither=Image.Dither.NONE)


def write_video(frames: list[Image.Image], path: Path, fps: float,
                colours: list[tuple[int, int, int]] | None = None) -> None:
    """Write ``frames`` to ``path`` (.gif or .mp4) through a temp file and ``os.replace``.

    GIF frames may be RGB (quantised here) or already palette images (``GifQuantiser``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        if suffix == ".gif":
            quantise = GifQuantiser(colours)
            quantised = [f if f.mode == "P" else quantise(f) for f in frames]
            duration = max(20, int(round(1000.0 / fps)))
            quantised[0].save(tmp, format="GIF", save_all=True, append_images=quantised[1:],
                              duration=duration, loop=0, optimize=False, disposal=1)
        elif suffix == ".mp4":
            arrays = np.stack([np.asarray(f.convert("RGB")) for f in frames])
            h, w = arrays.shape[1] // 2 * 2, arrays.shape[2] // 2 * 2  # H.264 needs even sizes
            arrays = np.ascontiguousarray(arrays[:, :h, :w])
            if _mp4_backend() == "ffmpeg":
                import imageio.v2 as iio2

                iio2.mimwrite(tmp, list(arrays), format="FFMPEG", fps=fps, codec="libx264",
                              macro_block_size=2)
            else:
                import imageio.v3 as iio

                iio.imwrite(tmp, arrays, plugin="pyav", codec="libx264", fps=fps)
        else:  # pragma: no cover - checked by main
            raise RenderError(f"unsupported output format {suffix!r}")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


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


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m agents.render",
        description="Render part of one episode of a controller as an animated GIF (or MP4): "
                    "the 3-D vertiport with labelled eVTOLs, the time of day, the last ATC "
                    "instruction, and per eVTOL its battery, status, schedule and events.",
    )
    ap.add_argument("--agent", default="random",
                    help=f"controller: one of {', '.join(sorted(BUILTIN))}, or an import path "
                         "'package.module:Class' (default: %(default)s)")
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


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except RenderError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    from marl_vertiport import vertiport_v0
    from marl_vertiport.config import ConfigError

    out = args.out or Path("runs/render") / f"{args.agent.replace(':', '_').replace('.', '_')}_{Path(str(args.config)).stem}.gif"
    try:
        policy = make_controller(args.agent)
    except AgentSpecError as exc:
        raise RenderError(str(exc)) from None
    _check_output(out)
    try:
        env = vertiport_v0.env(config=args.config, render_mode="rgb_array")
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

        colours = [_rgb(VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)]) for i in range(sim.n)]
        convert = GifQuantiser(colours) if out.suffix.lower() == ".gif" else None
        t0 = time.perf_counter()
        frames = record_episode(env, policy, args.seed, factory, start_step, n_steps, args.every,
                                progress=not args.no_progress, convert=convert)
    finally:
        env.close()
    write_video(frames, out, args.fps, colours)
    size_mb = out.stat().st_size / 1e6
    print(f"wrote {out} ({len(frames)} frames, {width}x{height}, {size_mb:.1f} MB, "
          f"{time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
