"""The status panel beside the 3-D view: the time of day and the day's progress, the last ATC
instruction and what it led to, one row per eVTOL (status, battery, schedule, events) and the
running totals."""

from __future__ import annotations

from typing import Any

from PIL import ImageDraw

from agents.render.style import (
    ACT_BG, AMBER, BG, BLUE, DIM, GREEN, LOW_BATTERY_PCT, RED, ROW_BG, STATUS_COLOUR,
    STATUS_LABEL, TEXT, describe_action, hhmm, node_short,
)
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE, PENDING_LANDING,
    PENDING_TAKEOFF, TAXIING,
)


class StatusPanel:
    """Draws the panel of a frame; its size, fonts and vehicle colours are the
    :class:`~agents.render.frames.FrameComposer`'s."""

    def __init__(self, frame: Any) -> None:
        self.frame = frame

    def __getattr__(self, name: str) -> Any:  # the frame's geometry, fonts and state
        return getattr(self.frame, name)

    def _schedule_text(self, v: int) -> tuple[str, tuple[int, int, int]]:
        sim = self.sim
        if bool(sim.lost[v]):
            return "vehicle lost for the rest of the day", RED
        kind = int(sim.pending_kind[v])
        tol = sim.cfg.schedule.on_time_tolerance_min
        now = float(sim.minute)
        due = float(sim.pending_time[v])
        delay = float(sim.delay[v])
        if kind == PENDING_TAKEOFF:
            if delay > 0:
                return f"take-off delayed {delay:.0f} min", RED
            if due - now > 0.5:
                colour = TEXT if due - now > tol else GREEN
                return f"take-off in {due - now:.0f} min ({hhmm(due)})", colour
            return f"take-off due now (by {hhmm(due + tol)})", GREEN
        if kind == PENDING_LANDING:
            if delay > 0:
                return f"landing delayed {delay:.0f} min", RED
            return f"land by {hhmm(due + tol)}", AMBER if due + tol - now <= 5 else TEXT
        status = int(sim.status[v])
        if status in (DEPARTING, AWAY):
            dest = int(sim.dest[v])
            back = " (returning)" if status == AWAY and bool(sim.returning[v]) else ""
            return f"trip to destination D{dest}{back}", DIM
        if status == OUT_OF_SERVICE:
            return "battery depleted: grounded", RED
        if status == TAXIING and sim.landing_cleared[v]:
            return "landing", DIM
        return "no flight scheduled", DIM

    def draw(self, d: ImageDraw.ImageDraw, step_reward: float | None) -> None:
        sim, s = self.sim, self.s
        x0 = self.view_w
        W = self.panel_w
        pad = max(3, int(6 * s))
        lh = self.line_h
        d.rectangle([x0, 0, self.width, self.height], fill=BG)
        # ---- header: clock, day progress, last instruction
        day_min = sim.cfg.schedule.episode_steps * sim.minutes_per_step
        d.text((x0 + pad, pad), hhmm(sim.minute), font=self.f_clock, fill=TEXT, anchor="lt")
        cb = d.textbbox((x0 + pad, pad), hhmm(sim.minute), font=self.f_clock, anchor="lt")
        d.text((cb[2] + pad, cb[3]), f"step {sim.step_count}", font=self.f_small, fill=DIM,
               anchor="ld")
        bar_y = cb[3] + max(2, int(3 * s))
        bar_h = max(2, int(3 * s))
        d.rectangle([x0 + pad, bar_y, x0 + W - pad, bar_y + bar_h], fill=ROW_BG)
        frac = min(1.0, float(sim.minute) / max(day_min, 1e-9))
        d.rectangle([x0 + pad, bar_y, x0 + pad + (W - 2 * pad) * frac, bar_y + bar_h], fill=BLUE)
        y = bar_y + bar_h + max(2, int(4 * s))
        info = sim.last_info or {}
        acting = self._acting
        if "action" in info:
            col = self.colours[acting]
            sw = lh - 3
            d.rectangle([x0 + pad, y + 1, x0 + pad + sw, y + 1 + sw], fill=col)
            d.text((x0 + pad + sw + 4, y), f"ATC \u2192 eVTOL {acting} at {hhmm(info['minute'])}",
                   font=self.f_bold, fill=TEXT)
            y += lh
            d.text((x0 + pad, y), self._fit(d, describe_action(sim, info), self.f_body,
                                            W - 2 * pad), font=self.f_body, fill=TEXT)
            y += lh
            rtxt = f"reward {step_reward:+.2f}" if step_reward is not None else ""
            d.text((x0 + pad, y), rtxt, font=self.f_small, fill=DIM)
            xr = x0 + W - pad
            for text, colour in reversed(self._outcomes(info)):
                d.text((xr, y), text, font=self.f_small, fill=colour, anchor="ra")
                xr = d.textbbox((xr, y), text, font=self.f_small, anchor="ra")[0] - 5
        else:
            d.text((x0 + pad, y), "start of the day", font=self.f_bold, fill=DIM)
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
            (f"total reward {m.total_reward:+.1f}", TEXT),
            (f"good take-offs {m.good_takeoffs}/{m.takeoffs} \u00b7 landings "
             f"{m.good_landings}/{m.landings}", TEXT),
            (f"vehicles lost {m.stranded_air + m.stranded_ground} \u00b7 contacts {m.contacts} "
             f"\u00b7 sep. losses {m.separation_losses}",
             RED if m.stranded_air + m.stranded_ground or m.contacts or m.separation_losses
             else TEXT),
            (f"unresolved conflicts {m.collisions} \u00b7 avoided {m.avoided_conflicts}",
             AMBER if m.collisions else TEXT),
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
            out.append(("\u2713 take-off ok" if good else "\u2717 bad take-off", GREEN if good else RED))
        elif info.get("takeoff_failed"):
            out.append(("\u2717 take-off failed", RED))
        elif info.get("landing"):
            good = bool(info.get("good_landing"))
            out.append(("\u2713 landing ok" if good else "\u2717 bad landing", GREEN if good else RED))
        if info.get("conflict"):
            avoided = info.get("reward_terms", {}).get("safety", 0.0) > 0
            out.append(("\u2713 avoided" if avoided else "\u2717 conflict", GREEN if avoided else RED))
        if info.get("commanded_action", info.get("action")) != info.get("action"):
            out.append(("misread", AMBER))
        return out

    def _draw_row(self, d: ImageDraw.ImageDraw, v: int, x0: int, y0: int, h: int, pad: int) -> None:
        sim, s, W, lh = self.sim, self.s, self.panel_w, self.line_h
        col = self.colours[v]
        status = int(sim.status[v])
        bg = ACT_BG if v == self._acting else ROW_BG
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
            where = f" {node_short(sim, node)}"
        elif node >= 0 and status in (TAXIING, ARRIVING):
            where = f" \u2192{node_short(sim, node)}"
        label, colour = STATUS_LABEL[status] + where, STATUS_COLOUR[status]
        if bool(sim.lost[v]):  # lost on the ground keeps its port: say it is lost
            label, colour = "LOST" + (f" ({STATUS_LABEL[status]}{where})"
                                      if status != OUT_OF_SERVICE else ""), RED
        d.text((right, y), label, font=self.f_body, fill=colour, anchor="ra")
        if v == self._acting:
            d.text((nb[2] + 3, y), "\u25c0", font=self.f_body, fill=TEXT)
        y += lh
        # line 2: battery bar and percent
        bat = float(sim.battery[v])
        bw = int((W - 2 * pad) * 0.5)
        bh = max(4, int(lh * 0.55))
        by = y + (lh - bh) // 2
        bcol = RED if bat < LOW_BATTERY_PCT else (AMBER if bat < 60 else GREEN)
        d.rectangle([x, by, x + bw, by + bh], outline=DIM, fill=(20, 22, 27))
        if bat > 0:
            d.rectangle([x + 1, by + 1, x + 1 + (bw - 2) * bat / 100.0, by + bh - 1], fill=bcol)
        thr_x = x + 1 + (bw - 2) * LOW_BATTERY_PCT / 100.0
        d.line([(thr_x, by - 1), (thr_x, by + bh + 1)], fill=TEXT)
        d.text((x + bw + 4, y), f"{bat:3.0f} %", font=self.f_body,
               fill=RED if bat < LOW_BATTERY_PCT else TEXT)
        marks = []
        if status == ON_CHARGER:
            marks.append(("\u26a1", GREEN))
        if bool(sim.conflict[v]):
            marks.append(("\u26a0 conflict", RED))
        if sim.avoid_layer[v] >= 0:
            marks.append((f"\u2191{sim.cfg.flight.avoid_altitudes_m[int(sim.avoid_layer[v])]:.0f}m", AMBER))
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
                extra.append(("took off", GREEN if info.get("good_takeoff") else RED))
            if info.get("landing"):
                extra.append(("cleared to land", GREEN if info.get("good_landing") else RED))
        done = float(sim.completed_delay[v])
        if done > 0:
            extra.append((f"late so far {done:.0f} min", DIM))
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
