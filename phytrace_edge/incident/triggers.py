"""What opens an incident: pure rules over the readings, plus a mark by hand.

- ``diagnostics``: a ``/diagnostics`` status entering INCIDENT_DIAGNOSTICS_LEVEL or
  worse (``warn`` < ``error`` < ``stale``). A status that stays at ERROR and is
  published every second is one trigger, when it entered ERROR, not one a second.
- ``rosout``: a ``/rosout`` record at INCIDENT_ROSOUT_LEVEL or worse (``error``,
  ``fatal``). Every such record is a trigger; inside an open window it only extends it.
- ``topic``: an INCIDENT_TRIGGERS condition (``/estop data == true``,
  ``/delivery/status payload.delivery_state == failed``) becoming true. Like a status,
  a condition that stays true is one trigger.
- ``manual``: ``phytrace-edge mark --reason TEXT`` or the ROS service ``~/mark``.

A condition reads a field of the topic's reading (a table topic: the handler's output,
docs/udm.md) or of the message as JSON (a TOPICS_EXTRA topic), by a dotted path.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

TriggerKind = Literal["diagnostics", "rosout", "topic", "manual"]
DIAGNOSTIC_SEVERITY = {"ok": 0, "unknown": 0, "warn": 1, "error": 2, "stale": 3}
ROSOUT_SEVERITY = {"debug": 0, "info": 1, "warn": 2, "error": 3, "fatal": 4}
MESSAGE_MAX_CHARS = 512
OPERATORS: dict[str, Callable[[Any, Any], bool]] = {
    "==": operator.eq,
    "!=": operator.ne,
    ">=": operator.ge,
    "<=": operator.le,
    ">": operator.gt,
    "<": operator.lt,
}


@dataclass(frozen=True)
class Trigger:
    """Why an incident opens, and when (the input's timeline: ``at_s`` monotonic,
    ``wall_s`` its stamp)."""

    kind: TriggerKind
    message: str
    at_s: float
    wall_s: float
    topic: str | None = None
    level: str | None = None


@dataclass(frozen=True)
class Condition:
    """One INCIDENT_TRIGGERS entry: ``topic path op value``."""

    topic: str
    path: tuple[str, ...]
    op: str
    value: Any

    def holds(self, data: Mapping[str, Any]) -> bool:
        """Whether the reading (or message data) meets the condition; a missing field
        or values that cannot be compared do not."""
        found: Any = data
        for key in self.path:
            if not isinstance(found, Mapping) or key not in found:
                return False
            found = found[key]
        try:
            return bool(OPERATORS[self.op](found, self.value))
        except TypeError:
            return False

    def describe(self) -> str:
        return f"{self.topic} {'.'.join(self.path)} {self.op} {self.value!r}"


@dataclass
class TriggerRules:
    """The rules of one bridge, and the state that makes a lasting condition one
    trigger (``observe`` is called with every reading, on the ingest threads, under
    the recorder's lock)."""

    diagnostics_level: str | None = "error"  # None: off
    rosout_level: str | None = "error"
    conditions: Sequence[Condition] = ()
    _alarming: set[tuple[str, str]] = field(default_factory=set)
    _holding: set[Condition] = field(default_factory=set)

    def topics(self) -> set[str]:
        """The topics whose readings the rules look at."""
        watched = {c.topic for c in self.conditions}
        if self.diagnostics_level is not None:
            watched.add("/diagnostics")
        if self.rosout_level is not None:
            watched.add("/rosout")
        return watched

    def observe(
        self, topic: str, data: Mapping[str, Any], at_s: float, wall_s: float
    ) -> list[Trigger]:
        """The triggers one reading fires (usually none)."""
        fired: list[Trigger] = []
        if topic == "/diagnostics" and self.diagnostics_level is not None:
            fired += self._diagnostics(data, at_s, wall_s)
        if topic == "/rosout" and self.rosout_level is not None:
            fired += self._rosout(data, at_s, wall_s)
        for condition in self.conditions:
            if condition.topic == topic:
                fired += self._condition(condition, data, at_s, wall_s)
        return fired

    def _diagnostics(self, data: Mapping[str, Any], at_s: float, wall_s: float) -> list[Trigger]:
        threshold = DIAGNOSTIC_SEVERITY[self.diagnostics_level or "error"]
        fired = []
        for status in data.get("statuses", []):
            key = (str(status.get("hardware_id", "")), str(status.get("name", "")))
            level = str(status.get("level", "unknown"))
            alarming = DIAGNOSTIC_SEVERITY.get(level, 0) >= threshold
            if alarming and key not in self._alarming:
                message = f"{key[1]}: {status.get('message', '')}".strip(": ")
                fired.append(
                    Trigger("diagnostics", shortened(message), at_s, wall_s, "/diagnostics", level)
                )
            if alarming:
                self._alarming.add(key)
            else:
                self._alarming.discard(key)
        return fired

    def _rosout(self, data: Mapping[str, Any], at_s: float, wall_s: float) -> list[Trigger]:
        level = str(data.get("level", ""))
        if ROSOUT_SEVERITY.get(level, 0) < ROSOUT_SEVERITY[self.rosout_level or "error"]:
            return []
        message = f"{data.get('logger', '')}: {data.get('message', '')}"
        return [Trigger("rosout", shortened(message), at_s, wall_s, "/rosout", level)]

    def _condition(
        self, condition: Condition, data: Mapping[str, Any], at_s: float, wall_s: float
    ) -> list[Trigger]:
        if not condition.holds(data):
            self._holding.discard(condition)
            return []
        if condition in self._holding:
            return []
        self._holding.add(condition)
        return [Trigger("topic", shortened(condition.describe()), at_s, wall_s, condition.topic)]


def shortened(text: str) -> str:
    return text if len(text) <= MESSAGE_MAX_CHARS else text[: MESSAGE_MAX_CHARS - 1] + "…"
