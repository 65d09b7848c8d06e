"""One frame: the engine's image with each eVTOL labelled (this module), and the status panel
beside it (:mod:`agents.render.panel`), in the colours and fonts of :mod:`agents.render.style`."""

from __future__ import annotations

import math

import numpy as np
from PIL import Image, ImageDraw

from agents.render.camera import DEFAULT_PITCH_DEG, DEFAULT_YAW_DEG, fit_camera
from agents.render.panel import StatusPanel
from agents.render.style import (
    AMBER, BG, BLUE, DIM, RED, SKY, TEXT, font, ink_on, node_short, overlap, rgb, short_action,
)
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.layout import HOVER_SPOT
from marl_vertiport.sim.schema import AWAY, OUT_OF_SERVICE
from marl_vertiport.sim.physics import VEHICLE_COLOURS


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
        self.colours = [rgb(VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)]) for i in range(sim.n)]
        s = self.height / 480.0
        self.s = s
        self.f_clock = font(max(10.0, 26 * s), bold=True)
        clock_h = self.f_clock.getbbox("00:00")[3] if hasattr(self.f_clock, "getbbox") else 26 * s
        pad = max(3, int(6 * s))
        # Header: clock, day bar, 3 lines; footer: 3 small lines; fleet rows share the rest,
        # 4 text lines per row (the body font shrinks for large fleets).
        body = 12.5 * s
        for _ in range(20):
            lh = math.ceil(body * 1.25)
            header_h = pad + clock_h + 2 * max(2, int(3 * s)) + max(2, int(4 * s)) + 3 * lh + pad
            footer_h = 4 * math.ceil(body * 0.88 * 1.25) + 2 * pad
            row_h = (self.height - header_h - footer_h) / max(sim.n, 1)
            if row_h >= 4.2 * lh or body <= 7.0:
                break
            body = max(7.0, body * 0.92)
        self.f_body = font(body)
        self.f_bold = font(body, bold=True)
        self.f_small = font(max(6.0, body * 0.88))
        self.f_label = font(max(7.0, 11 * s), bold=True)
        self.f_port = font(max(6.0, 9 * s))
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
        self.panel = StatusPanel(self)

    # ------------------------------------------------------------------ public
    def raw_view(self) -> np.ndarray:
        """The 3-D view alone (no overlay), ``(height, view_w, 3)``."""
        return self.camera.image(self.sim)

    def compose(self, step_reward: float | None = None, view: np.ndarray | None = None,
                decision: dict | None = None) -> Image.Image:
        """The full frame for the simulator's current state, as an RGB PIL image; with
        ``decision`` (a row of :class:`agents.controllers.decisions.DecisionLog`), a strip over
        the top of the 3-D view shows the recommendation, the alternatives' probabilities and
        why the other actions are masked."""
        view = self.raw_view() if view is None else view
        frame = Image.new("RGB", (self.width, self.height), BG)
        view = np.array(view, copy=True)
        sky = (view[:, :, 0] == 255) & (view[:, :, 1] == 255) & (view[:, :, 2] == 255)  # clear colour
        view[sky] = SKY
        frame.paste(Image.fromarray(view), (0, 0))
        draw = ImageDraw.Draw(frame)
        info = self.sim.last_info or {}
        self._acting = (int(str(info["acting_agent"]).rsplit("_", 1)[-1])
                        if "acting_agent" in info else -1)
        self._draw_scene_labels(draw)
        if decision is not None:
            self._draw_decision(draw, decision)
        self.panel.draw(draw, step_reward)
        return frame

    # ------------------------------------------------------------------ decision strip
    def decision_lines(self, row: dict) -> list[tuple[str, tuple[int, int, int]]]:
        """The strip's lines for a decision-log row: the recommendation and who decided it,
        the policy's probabilities (learned controllers), the masked actions' reasons (those
        masked by their status left out: they are never an option)."""
        who = row["agent"].replace("evtol_", "eVTOL ")
        lines = [(f"{who} ({row['status'].replace('_', ' ')}, {row['battery_pct']:.0f} %) \u2192 "
                  f"{short_action(row['recommendation_name'])}, by {row['decided_by']}", TEXT)]
        if row["probabilities"]:
            alts = " \u00b7 ".join(f"{short_action(a)} {p:.2f}" for a, p in
                                    list(row["probabilities"].items())[:4])
            lines.append((f"policy: {alts}", BLUE))
        masked = [f"{short_action(a)} {r.replace('separation: ', 'sep. ')}"
                  for a, r in row["masked"].items() if not r.startswith("status")]
        if masked:
            lines.append(("masked: " + " \u00b7 ".join(masked), AMBER))
        if row["events"]:
            bad = any(w in row["events"] for w in ("lost", "contact", "separation", "failed"))
            lines.append(("then: " + row["events"], RED if bad else DIM))
        return lines

    def _draw_decision(self, d: ImageDraw.ImageDraw, row: dict) -> None:
        pad = max(2, int(4 * self.s))
        width = self.view_w - 2 * pad
        lines = self.decision_lines(row)
        h = len(lines) * self.small_h + 2 * pad
        d.rectangle([0, 0, self.view_w, h], fill=BG)  # the panel's dark ground and inks
        y = pad
        for text, colour in lines:
            d.text((pad, y), StatusPanel._fit(d, text, self.f_small, width), font=self.f_small,
                   fill=colour)
            y += self.small_h

    # ------------------------------------------------------------------ 3-D view
    def _draw_scene_labels(self, d: ImageDraw.ImageDraw) -> None:
        sim, s = self.sim, self.s
        # Ports and hover spots: a short name next to each.
        for k, (x, y) in enumerate(self._port_px):
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            if sim.layout.node_type[k] == HOVER_SPOT:
                d.text((x + 2 * s, y), node_short(sim, k), font=self.f_port, fill=(95, 85, 30),
                       anchor="lm")
            else:
                d.text((x, y + 1), node_short(sim, k), font=self.f_port, fill=(40, 40, 50),
                       anchor="mt")
        self._draw_scene_key(d)
        self._draw_failed_chargers(d)
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
                d.line([tuple(vpx[a]), tuple(vpx[b])], fill=RED, width=max(1, int(2 * s)))
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
            if status == OUT_OF_SERVICE or bool(sim.lost[v]):
                c = 5 * s
                d.line([(x - c, y - c), (x + c, y + c)], fill=RED, width=lw)
                d.line([(x - c, y + c), (x + c, y - c)], fill=RED, width=lw)
            text = str(v) + (f" {alt:.0f}m" if airborne else "")
            if bool(sim.conflict[v]):
                text += " !"
            outline = (20, 20, 20)
            if status == OUT_OF_SERVICE or bool(sim.lost[v]) or bool(sim.conflict[v]):
                outline = RED
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
                cost = sum(overlap(box, other) for other in placed)
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
            d.text(at, text, font=self.f_label, fill=ink_on(col), anchor=anchor)

    def _draw_failed_chargers(self, d: ImageDraw.ImageDraw) -> None:
        """A red ring and cross on each charging port whose charger failed in the last step."""
        s = self.s
        for k in getattr(self.sim, "last_failed_chargers", ()):
            x, y = self._port_px[k]
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            r, lw = 9 * s, max(1, int(round(2 * s)))
            d.ellipse([x - r, y - r * 0.7, x + r, y + r * 0.7], outline=RED, width=lw)
            d.line([(x - r * 0.6, y - r * 0.4), (x + r * 0.6, y + r * 0.4)], fill=RED, width=lw)
            d.line([(x - r * 0.6, y + r * 0.4), (x + r * 0.6, y - r * 0.4)], fill=RED, width=lw)

    def _draw_scene_key(self, d: ImageDraw.ImageDraw) -> None:
        """The key of the view in its bottom-left corner: the ground markings, and what every
        tag and mark on a vehicle means."""
        s = self.s
        items = [((62, 62, 74), "P port"), ((30, 160, 65), "C charger"), ((235, 200, 50), "H hover spot"),
                 ((75, 75, 220), "airspace edge"), (RED, "red ring x: charger failed"),
                 ((200, 200, 200), "tag '2 4m': eVTOL 2, 4 m up"),
                 ((245, 245, 245), "tag '2 +11m': 11 m beyond the edge"),
                 ((255, 255, 255), "white edge: acting; '!': conflict"),
                 (RED, "red x / red edge: vehicle lost")]
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
            if not any(overlap(box, o) for o in placed):
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

