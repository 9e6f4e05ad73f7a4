"""The live page's data, per robot: the latest ``telemetry.periodic`` event and how far
behind the present it is (``lag_s``: after an outage, how soon the live lane brought
the robot's present), its event rate, the recent battery and speed series, its route
(``track``), a timeline of errors, task transitions and log records, the latest
``bridge.health`` figures and the latest value of each extra topic. In memory, for
people watching; the record is the store."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import orjson

from phytrace_edge.udm.event import parse_timestamp

SERIES_SECONDS = 300.0
SERIES_POINTS = 600
TRACK_POINTS = 2000
TIMELINE_ITEMS = 40
RATE_WINDOW_S = 10.0
VALUE_CHARS = 300  # an extra topic's latest data, as JSON text, cut for the page


@dataclass
class Robot:
    events: int = 0
    latest: dict[str, Any] = field(default_factory=dict)
    series: deque[dict[str, float]] = field(default_factory=lambda: deque(maxlen=SERIES_POINTS))
    track: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=TRACK_POINTS))
    timeline: list[dict[str, Any]] = field(default_factory=list)
    seen_errors: set[tuple[str, str]] = field(default_factory=set)
    health: dict[str, Any] = field(default_factory=dict)
    topics: dict[str, dict[str, Any]] = field(default_factory=dict)
    arrivals: deque[tuple[float, int]] = field(default_factory=deque)

    def add(self, event: dict[str, Any]) -> None:
        self.events += 1
        kind = event.get("event_type", "telemetry.periodic")
        topic = str(event.get("topic"))
        if kind == "telemetry.periodic":
            self._add_periodic(event)
        elif kind == "log.record":
            self._note(event.get("captured_at"), "log", event.get("level"), _log_text(event))
        elif kind == "bridge.health" and _newer(event, self.health):
            self.health = event
        elif kind == "telemetry.topic" and _newer(event, self.topics.get(topic, {})):
            self.topics[topic] = {
                "type": event.get("type"),
                "captured_at": event.get("captured_at"),
                "value": orjson.dumps(event.get("data")).decode()[:VALUE_CHARS],
            }

    def _add_periodic(self, event: dict[str, Any]) -> None:
        if _newer(event, self.latest):
            self.latest = event
        point = _point(event)
        if point is not None:
            self.series.append(point)
        place = _place(event)
        if place is not None:
            self.track.append(place)
        operational = event.get("operational", {})
        for error in operational.get("errors", []):
            key = (str(error.get("name")), str(error.get("first_seen_at")))
            if error.get("level") in ("error", "stale") and key not in self.seen_errors:
                self.seen_errors.add(key)
                text = f"{error.get('name')}: {error.get('message', '')}"
                at = error.get("first_seen_at") or event.get("captured_at")
                self._note(at, "error", error.get("level"), text)
        for change in operational.get("transitions", []):
            text = f"task {change.get('from', '?')} -> {change.get('to')}"
            self._note(change.get("at"), "task", "info", text)

    def _note(self, at: Any, kind: str, level: Any, text: str) -> None:
        """Keep the newest TIMELINE_ITEMS items, newest first."""
        self.timeline.append({"at": str(at), "kind": kind, "level": str(level), "text": text})
        self.timeline.sort(key=lambda item: item["at"], reverse=True)
        del self.timeline[TIMELINE_ITEMS:]
        if len(self.seen_errors) > 10 * TIMELINE_ITEMS:
            self.seen_errors.clear()


class Board:
    def __init__(self) -> None:
        self.robots: dict[str, Robot] = {}

    def add(self, events: list[dict[str, Any]], now: float | None = None) -> None:
        now = time.time() if now is None else now
        for event in events:
            self.robots.setdefault(str(event.get("source_id")), Robot()).add(event)
        for source in {str(e.get("source_id")) for e in events}:
            count = sum(1 for e in events if str(e.get("source_id")) == source)
            self.robots[source].arrivals.append((now, count))

    def summary(self, now: float | None = None) -> list[dict[str, Any]]:
        now = time.time() if now is None else now
        out = []
        for source_id, robot in sorted(self.robots.items()):
            while robot.arrivals and robot.arrivals[0][0] < now - RATE_WINDOW_S:
                robot.arrivals.popleft()
            recent = [p for p in robot.series if p["t"] >= now - SERIES_SECONDS]
            latest_at = _captured_at(robot.latest)
            out.append(
                {
                    "source_id": source_id,
                    "events": robot.events,
                    "rate_eps": round(sum(n for _, n in robot.arrivals) / RATE_WINDOW_S, 2),
                    "latest": robot.latest,
                    "lag_s": None if latest_at is None else round(max(0.0, now - latest_at), 1),
                    "series": recent,
                    "track": list(robot.track),
                    "timeline": robot.timeline,
                    "health": _health(robot.health),
                    "topics": dict(sorted(robot.topics.items())),
                }
            )
        return out


def _newer(event: dict[str, Any], than: dict[str, Any]) -> bool:
    return bool(event.get("captured_at", "") >= than.get("captured_at", ""))


def _captured_at(event: dict[str, Any]) -> float | None:
    return _seconds(event.get("captured_at"))


def _seconds(stamp: Any) -> float | None:
    try:
        return parse_timestamp(str(stamp))
    except ValueError:
        return None


def _log_text(event: dict[str, Any]) -> str:
    suppressed = event.get("suppressed")
    more = f" (+{suppressed} held back)" if suppressed else ""
    return f"{event.get('logger')}: {event.get('message')}{more}"


def _health(event: dict[str, Any]) -> dict[str, Any]:
    """The figures of a ``bridge.health`` event the page shows."""
    if not event:
        return {}
    queue = event.get("queue", {})
    return {
        "captured_at": event.get("captured_at"),
        "healthy": event.get("healthy"),
        "problems": event.get("problems", []),
        "queue_depth": queue.get("depth"),
        "oldest_age_s": queue.get("oldest_age_s"),
        "send_rate_eps": event.get("send_rate_eps"),
        "drops": sum(event.get("drops", {}).values()),
        "uptime_s": event.get("uptime_s"),
        "version": event.get("version"),
    }


def _point(event: dict[str, Any]) -> dict[str, float] | None:
    t = _captured_at(event)
    if t is None:
        return None
    point = {"t": t}
    soc = event.get("power", {}).get("battery", {}).get("state_of_charge_pct")
    speed = event.get("motion", {}).get("speed_mps")
    if isinstance(soc, (int, float)):
        point["soc"] = float(soc)
    if isinstance(speed, (int, float)):
        point["speed"] = float(speed)
    return point


def _place(event: dict[str, Any]) -> dict[str, Any] | None:
    """Where the robot was: ``x``/``y`` in metres from ``location.local`` (frame
    ``local``), else longitude and latitude (frame ``geo``)."""
    location = event.get("location", {})
    local = location.get("local", {})
    for frame, x, y in (
        ("local", local.get("x_m"), local.get("y_m")),
        ("geo", location.get("longitude"), location.get("latitude")),
    ):
        if isinstance(x, (int, float)) and isinstance(y, (int, float)):
            return {"x": float(x), "y": float(y), "frame": frame}
    return None
