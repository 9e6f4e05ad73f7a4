"""What happens between two sample ticks and must not vanish.

A diagnostics ERROR that lasts 50 ms, a delivery that goes ``arriving -> delivered ->
returning`` within one tick, two goals sent in a row: each is kept here until the next
event takes it. These classes are plain state machines; the builder serialises calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from phytrace_edge.ingest.readings import (
    DeliveryStatusReading,
    DiagnosticStatusFields,
    GoalReading,
)
from phytrace_edge.udm.event import format_timestamp

MAX_ITEMS_PER_EVENT = 256
_SEVERITY = {"unknown": 0, "warn": 1, "stale": 2, "error": 3}
_ALARM_LEVELS = ("error", "stale")


@dataclass
class DiagnosticsTracker:
    """Non-OK diagnostic statuses: those active now, and those seen since the last event.

    A status is keyed by (hardware_id, name). It is *active* while its latest level is
    not OK. Every non-OK status observed since the last ``take`` is reported once even
    if it has cleared since, with the worst level seen and how often it was seen.
    """

    active: dict[tuple[str, str], DiagnosticStatusFields] = field(default_factory=dict)
    pending: dict[tuple[str, str], dict[str, Any]] = field(default_factory=dict)
    alarming: set[tuple[str, str]] = field(default_factory=set)  # at ERROR or STALE now
    alarm_changed: bool = False  # a status entered or left ERROR/STALE since the last take

    def observe(self, statuses: list[DiagnosticStatusFields], at_wall_s: float) -> None:
        for status in statuses:
            key = (status.get("hardware_id", ""), status["name"])
            self._note_alarm(key, status["level"] in _ALARM_LEVELS)
            if status["level"] == "ok":
                self.active.pop(key, None)
                continue
            self.active[key] = status
            seen = self.pending.get(key)
            if seen is None:
                if len(self.pending) >= MAX_ITEMS_PER_EVENT:
                    continue
                seen = {**status, "occurrences": 0, "first_seen_at": format_timestamp(at_wall_s)}
                self.pending[key] = seen
            worst = max(seen["level"], status["level"], key=_SEVERITY.__getitem__)
            seen.update(status, level=worst)
            seen["occurrences"] += 1

    def _note_alarm(self, key: tuple[str, str], alarm: bool) -> None:
        if alarm != (key in self.alarming):
            self.alarm_changed = True
            if alarm:
                self.alarming.add(key)
            else:
                self.alarming.discard(key)

    def take_alarm_change(self) -> bool:
        """Whether a status entered or left ERROR/STALE since the last call."""
        changed, self.alarm_changed = self.alarm_changed, False
        return changed

    def take(self, include_active: bool) -> list[dict[str, Any]]:
        """Errors for the next event; clears what was seen since the last one.

        ``include_active`` is False when /diagnostics has gone stale: its last word is
        then no longer reported as the current state.
        """
        errors = []
        for key, seen in self.pending.items():
            errors.append({**seen, "active": include_active and key in self.active})
        if include_active:
            for key, status in self.active.items():
                if key not in self.pending:
                    errors.append({**status, "active": True})
        self.pending = {}
        return errors[:MAX_ITEMS_PER_EVENT]


@dataclass
class TransitionTracker:
    """Task/delivery state changes seen on /delivery/status since the last event."""

    last_state: str | None = None
    last_task: str | None = None
    pending: list[dict[str, Any]] = field(default_factory=list)

    def observe(self, reading: DeliveryStatusReading, at_wall_s: float) -> None:
        payload = reading.get("payload", {})
        task = reading.get("task", {})
        state = payload.get("delivery_state") or task.get("status")
        task_id = task.get("task_id")
        if state is None or (state == self.last_state and task_id == self.last_task):
            return
        transition = {"at": format_timestamp(at_wall_s), "to": state}
        if task_id is not None:
            transition["task_id"] = task_id
        if self.last_state is not None:
            transition["from"] = self.last_state
        self.last_state, self.last_task = state, task_id
        if len(self.pending) < MAX_ITEMS_PER_EVENT:
            self.pending.append(transition)

    def take(self) -> list[dict[str, Any]]:
        taken, self.pending = self.pending, []
        return taken


@dataclass
class GoalTracker:
    """Goals received since the last event (the latest is also the current goal).

    A goal with the stamp and pose of the previous one is that goal again, not a new
    one: a latched goal replayed to a subscription re-created as transient-local."""

    pending: list[dict[str, Any]] = field(default_factory=list)
    last_key: tuple[Any, ...] | None = None

    def observe(self, reading: GoalReading, at_wall_s: float) -> None:
        goal = reading.get("goal")
        if goal is None:
            return
        key = (reading.get("stamp_ns"), *sorted(goal.items()))
        if key == self.last_key:
            return
        self.last_key = key
        if len(self.pending) < MAX_ITEMS_PER_EVENT:
            self.pending.append({**goal, "received_at": format_timestamp(at_wall_s)})

    def take(self) -> list[dict[str, Any]]:
        taken, self.pending = self.pending, []
        return taken
