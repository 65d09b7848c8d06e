"""The per-decision log of an episode, for an operator: at every turn, what the controller
recommends, the alternatives it weighed (with their probabilities, for the learned ATC), and why
each masked alternative is masked.

:class:`DecisionLog` is a pair of hooks for :func:`agents.controllers.episode.run_episode`
(``before_step``, ``after_step``). Before the controller acts it reads the acting eVTOL's mask,
the simulator's reasons for every masked action (:meth:`VertiportSim.mask_reasons`: ``status``,
``occupancy``, ``energy``, ``separation: evtol_2, ...``) and, where the controller has them,
its probabilities over the legal actions (:func:`action_probabilities`); after the step, the
action taken, who decided it (the policy, the dispatcher it handed the decision to, or the
look-ahead guard that changed it), the step's reward and what happened. Reading these changes
nothing in the episode (a test plays the same days with and without the log).

One row per turn (:data:`COLUMNS`)::

    step, minute, agent, status, battery_pct, legal        the turn and the acting eVTOL
    recommendation, recommendation_name, decided_by         what the controller gave
    policy_choice, policy_probability                       the learned policy's own choice
    probabilities                                           legal action -> probability
    masked                                                  masked action -> reason
    reward, events                                          the step's reward and outcomes

:meth:`DecisionLog.write` writes ``<stem>.csv`` (``probabilities`` and ``masked`` as
``"name p; name p"`` and ``"name: reason; ..."``) and ``<stem>.json`` (the same rows, nested).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.files import write_atomic
from marl_vertiport.sim.schema import STATUS_NAMES

__all__ = ["COLUMNS", "DecisionLog", "action_probabilities", "format_events"]

COLUMNS = ("step", "minute", "agent", "status", "battery_pct", "legal", "recommendation",
           "recommendation_name", "decided_by", "policy_choice", "policy_probability",
           "probabilities", "masked", "reward", "events")


def action_probabilities(policy: Any, observation: dict) -> np.ndarray | None:
    """``policy``'s probability of each action ``(A,)`` (0 on masked ones) for ``observation``,
    or ``None`` for a controller that has none (the rules)."""
    fn = getattr(policy, "action_probabilities", None)
    if fn is None:
        return None
    probs = fn(observation)
    return None if probs is None else np.asarray(probs, dtype=np.float64)


def format_events(info: dict, lost: list[int] | None = None) -> str:
    """What the step led to, in words, from the env's step info (``""``: nothing of note);
    ``lost``: the vehicles lost on the step, named in place of the count."""
    out = []
    if info.get("takeoff"):
        out.append("take-off" if info.get("good_takeoff") else "take-off off schedule")
    if info.get("takeoff_failed"):
        out.append("take-off failed")
    if info.get("landing"):
        out.append("landing" if info.get("good_landing") else "landing off schedule")
    if info.get("conflict"):
        out.append("conflict predicted")
    for key, label in (("separation_losses", "separation lost"), ("contacts", "contact"),
                       ("vehicles_lost", "vehicle lost"), ("battery_depletions", "battery depleted"),
                       ("charger_failures", "charger failure"), ("gusts", "gust")):
        n = int(info.get(key, 0) or 0)
        if key == "vehicles_lost" and lost:
            out.append("vehicle lost: " + ", ".join(f"evtol_{v}" for v in lost))
        elif n:
            out.append(label if n == 1 else f"{label} x{n}")
    if info.get("commanded_action", info.get("action")) != info.get("action"):
        out.append("instruction misread")
    return "; ".join(out)


def _decided_by(policy: Any) -> str:
    """Who took the last decision of ``policy``: the look-ahead (it changed the choice), the
    rollout policy it hands decisions to, the proposer, or the policy itself."""
    name = getattr(policy, "name", type(policy).__name__)
    if getattr(policy, "last_changed", False):
        return f"{name}: look-ahead"
    own = getattr(policy, "own_rollout_policy", None)
    if getattr(policy, "last_deferred", False):
        return f"{name}: {getattr(own, 'name', 'rollout policy')}"
    proposer = getattr(policy, "proposer", None)
    if proposer is not None and own is not None:
        return f"{name}: {getattr(proposer, 'name', 'proposer')}"
    return name


class DecisionLog:
    """The rows of one episode's turns; see the module docstring.

    Args:
        policy: the controller whose decisions are logged (the one ``run_episode`` runs).
    """

    def __init__(self, policy: Any) -> None:
        self.policy = policy
        self.rows: list[dict[str, Any]] = []
        self._pending: dict[str, Any] | None = None
        self._reward_before = 0.0
        self._lost_before = np.zeros(0, dtype=bool)

    def before_step(self, agent: str, observation: dict, env: Any) -> None:
        sim = env.unwrapped.sim
        v = int(sim.acting)
        names = sim.actions.names(sim.layout)
        mask = np.asarray(observation["action_mask"])
        legal = np.flatnonzero(mask)
        probs = action_probabilities(self.policy, observation)
        row: dict[str, Any] = {
            "step": int(sim.step_count), "minute": float(sim.minute), "agent": agent,
            "status": STATUS_NAMES[int(sim.status[v])], "battery_pct": round(float(sim.battery[v]), 2),
            "legal": int(legal.size),
            "probabilities": {}, "policy_choice": "", "policy_probability": None,
            "masked": {names[a]: reason for a, reason in sorted(sim.mask_reasons(v).items())},
        }
        if probs is not None:
            order = sorted(legal.tolist(), key=lambda a: (-probs[a], a))
            row["probabilities"] = {names[a]: round(float(probs[a]), 4) for a in order}
            row["policy_choice"] = names[order[0]]
            row["policy_probability"] = round(float(probs[order[0]]), 4)
        self._pending = row
        self._reward_before = float(sim.metrics.total_reward)
        self._lost_before = np.asarray(sim.lost, dtype=bool).copy()

    def after_step(self, agent: str, action: int, env: Any) -> None:
        sim = env.unwrapped.sim
        row = self._pending
        if row is None:  # pragma: no cover - run_episode always calls before_step first
            raise RuntimeError("DecisionLog.after_step without before_step")
        self._pending = None
        names = sim.actions.names(sim.layout)
        row.update(recommendation=int(action), recommendation_name=names[int(action)],
                   decided_by=_decided_by(self.policy),
                   reward=round(float(sim.metrics.total_reward) - self._reward_before, 4),
                   events=format_events(sim.last_info or {}, np.flatnonzero(
                       np.asarray(sim.lost, dtype=bool) & ~self._lost_before).tolist()))
        self.rows.append({k: row[k] for k in COLUMNS})

    @property
    def last(self) -> dict[str, Any] | None:
        """The last row logged (the decision of the step just taken), or ``None``."""
        return self.rows[-1] if self.rows else None

    def to_csv(self, rows: list[dict[str, Any]] | None = None) -> str:
        """``rows`` (default: every turn logged) as CSV, one line a turn."""
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in self.rows if rows is None else rows:
            flat = dict(row)
            flat["probabilities"] = "; ".join(f"{k} {p:.4f}" for k, p in row["probabilities"].items())
            flat["masked"] = "; ".join(f"{k}: {r}" for k, r in row["masked"].items())
            flat["policy_probability"] = "" if row["policy_probability"] is None else row["policy_probability"]
            writer.writerow(flat)
        return buf.getvalue()

    def choices(self) -> list[dict[str, Any]]:
        """The real decisions: the rows whose vehicle had more than one legal action (a turn
        with one legal action decides nothing)."""
        return [row for row in self.rows if row["legal"] > 1]

    def write(self, stem: str | Path, meta: dict[str, Any] | None = None
              ) -> tuple[Path, Path, Path]:
        """Write ``<stem>.csv`` and ``<stem>.json`` (every turn, and ``meta`` beside them), and
        ``<stem>.choices.csv`` (the real decisions only, :meth:`choices`), each atomically;
        returns the three paths."""
        stem = Path(stem)
        csv_path, json_path = stem.with_name(stem.name + ".csv"), stem.with_name(stem.name + ".json")
        choices_path = stem.with_name(stem.name + ".choices.csv")
        write_atomic(csv_path, self.to_csv())
        write_atomic(choices_path, self.to_csv(self.choices()))
        write_atomic(json_path, json.dumps({"meta": meta or {}, "columns": list(COLUMNS),
                                            "rows": self.rows}, indent=1))
        return csv_path, json_path, choices_path
