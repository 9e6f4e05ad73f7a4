"""``log.record`` events from ``/rosout``: the robot's ROS log at or above
ROSOUT_MIN_LEVEL, burst-limited per logger.

Each logger may send ``burst`` records per minute; the rest are counted, and the next
record that logger sends says how many were held back (``suppressed``). The bridge's
own node never feeds its logs back into its own stream: records of the logger
``phytrace_edge`` (and its children) are skipped.
"""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass
from typing import Any

from phytrace_edge.builder.defaults import ROSOUT_LEVELS
from phytrace_edge.builder.envelope import classify_stamp, envelope
from phytrace_edge.ingest.readings import LogReading
from phytrace_edge.udm.types import LogRecordEvent, UdmIdentity

EVENT_TYPE_LOG = "log.record"
WINDOW_S = 60.0
OWN_LOGGER = "phytrace_edge"  # the bridge's node name (ingest.sources.base.NODE_NAME)
READY_MAX = 10_000
LOGGERS_MAX = 4096  # windows kept; a flood of new logger names cannot grow memory


@dataclass
class _Window:
    started_mono_s: float
    sent: int = 0
    held_back: int = 0  # since this logger's last record


class LogRecords:
    """Records in (``observe``), records to send out (``take``), with counts of what
    was skipped: ``below_level``, ``own`` (the bridge's) and ``suppressed`` (burst)."""

    def __init__(self, min_level: str, burst: int, window_s: float = WINDOW_S) -> None:
        self._min_rank = ROSOUT_LEVELS.index(min_level)
        self._burst, self._window_s = burst, window_s
        self._lock = threading.Lock()
        self._windows: dict[str, _Window] = {}
        self._ready: list[tuple[dict[str, Any], float]] = []
        self.counts: Counter[str] = Counter()
        self.suppressed_by_logger: Counter[str] = Counter()

    def observe(self, reading: LogReading, now_mono_s: float) -> None:
        logger = reading["logger"]
        with self._lock:
            if ROSOUT_LEVELS.index(reading["level"]) < self._min_rank:
                self.counts["below_level"] += 1
                return
            if logger == OWN_LOGGER or logger.startswith(OWN_LOGGER + "."):
                self.counts["own"] += 1
                return
            window = self._window(logger, now_mono_s)
            if window.sent >= self._burst or len(self._ready) >= READY_MAX:
                window.held_back += 1
                self.counts["suppressed"] += 1
                self.suppressed_by_logger[logger] += 1
                return
            window.sent += 1
            record = dict(reading)
            if window.held_back:
                record["suppressed"], window.held_back = window.held_back, 0
            self.counts["records"] += 1
            self._ready.append((record, now_mono_s))

    def take(self) -> list[tuple[dict[str, Any], float]]:
        """The records to send, with when each was received, oldest first."""
        with self._lock:
            ready, self._ready = self._ready, []
        return ready

    def _window(self, logger: str, now_mono_s: float) -> _Window:
        window = self._windows.get(logger)
        if window is None or now_mono_s - window.started_mono_s >= self._window_s:
            held_back = window.held_back if window else 0
            if window is None and len(self._windows) >= LOGGERS_MAX:
                self._windows.pop(next(iter(self._windows)))
            window = self._windows[logger] = _Window(now_mono_s, held_back=held_back)
        return window


def log_event(
    identity: UdmIdentity,
    record: dict[str, Any],
    captured_at_s: float,
    use_sim_time: bool = False,
) -> LogRecordEvent:
    """One ``log.record`` event (docs/udm.md)."""
    event: LogRecordEvent = {
        **envelope(identity, EVENT_TYPE_LOG, captured_at_s),
        "level": record["level"],
        "logger": record["logger"],
        "message": record["message"],
        **classify_stamp(record.get("stamp_ns"), captured_at_s, use_sim_time),
    }
    if "file" in record:
        event["file"] = record["file"]
    if "function" in record:
        event["function"] = record["function"]
    if "line" in record:
        event["line"] = record["line"]
    if "suppressed" in record:
        event["suppressed"] = record["suppressed"]
    return event
