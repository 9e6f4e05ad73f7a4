"""The live page's data: per robot, the latest event, how far behind the present it is
(``lag_s``: after an outage, how soon the live lane brought the robot's present), its
event rate and the recent battery and speed series. In memory, for people watching;
the record is the store."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

SERIES_SECONDS = 300.0
SERIES_POINTS = 600
RATE_WINDOW_S = 10.0


@dataclass
class Robot:
    events: int = 0
    latest: dict[str, Any] = field(default_factory=dict)
    series: deque[dict[str, float]] = field(default_factory=lambda: deque(maxlen=SERIES_POINTS))
    arrivals: deque[tuple[float, int]] = field(default_factory=deque)


class Board:
    def __init__(self) -> None:
        self.robots: dict[str, Robot] = {}

    def add(self, events: list[dict[str, Any]], now: float | None = None) -> None:
        now = time.time() if now is None else now
        for event in events:
            robot = self.robots.setdefault(str(event.get("source_id")), Robot())
            robot.events += 1
            if event.get("captured_at", "") >= robot.latest.get("captured_at", ""):
                robot.latest = event
            point = _point(event)
            if point is not None:
                robot.series.append(point)
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
                }
            )
        return out


def _captured_at(event: dict[str, Any]) -> float | None:
    try:
        return datetime.fromisoformat(str(event["captured_at"]).replace("Z", "+00:00")).timestamp()
    except (KeyError, ValueError):
        return None


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
