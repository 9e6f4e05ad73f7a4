"""The running service's heartbeat: figures ``status`` reads from another process.

Every ``HEARTBEAT_S`` the service rewrites one row of the queue database with its
sender's and topics' figures. The row survives the process, so ``status`` can say
when the service last lived and what it last saw, whether or not it runs now.
"""

from __future__ import annotations

import os
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from phytrace_edge import __version__
from phytrace_edge.queue import QueueStore

HEARTBEAT_S = 2.0
RATE_SMOOTHING = 0.3  # weight of the newest interval in the send-rate average


@dataclass
class Rates:
    """Per-second rates from counters sampled at each heartbeat (exponential average)."""

    previous: dict[str, float] = field(default_factory=dict)
    at: float | None = None
    rates: dict[str, float] = field(default_factory=dict)

    def update(self, counters: dict[str, float], now: float) -> dict[str, float]:
        if self.at is not None and now > self.at:
            for name, value in counters.items():
                instant = max(0.0, value - self.previous.get(name, value)) / (now - self.at)
                old = self.rates.get(name, instant)
                self.rates[name] = old + RATE_SMOOTHING * (instant - old)
        self.previous, self.at = dict(counters), now
        return {name: round(rate, 3) for name, rate in self.rates.items()}


def write_state(store: QueueStore, document: dict[str, Any], running: bool) -> None:
    with store.transaction() as cursor:
        cursor.execute(
            "INSERT OR REPLACE INTO service_state(id, heartbeat_at, running, document) "
            "VALUES (1, ?, ?, ?)",
            (store.now(), int(running), orjson.dumps(document).decode()),
        )


def service_document(
    settings_summary: dict[str, Any],
    sender: dict[str, Any],
    topics: dict[str, Any],
    extra: dict[str, Any],
    started_at: float,
) -> dict[str, Any]:
    return {
        "pid": os.getpid(),
        "version": __version__,
        "started_at": started_at,
        **settings_summary,
        "sender": sender,
        "topics": topics,
        **extra,
    }


@dataclass(frozen=True)
class Snapshot:
    """What ``status`` read: the queue's counters and the service's last heartbeat."""

    counters: dict[str, int]
    oldest_queued_at: float | None
    file_bytes: int
    quarantined: str | None
    heartbeat_at: float | None
    running: bool
    service: dict[str, Any]


def read_snapshot(path: Path, now: Callable[[], float] = time.time) -> Snapshot | None:
    """Read the queue file without writing to it; None when there is no queue file."""
    if not path.exists():
        return None
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=5)
    try:
        counters = dict(db.execute("SELECT name, value FROM counters"))
        oldest = db.execute("SELECT queued_at FROM events ORDER BY id LIMIT 1").fetchone()
        quarantined = db.execute("SELECT value FROM meta WHERE key = 'quarantined'").fetchone()
        try:
            row = db.execute(
                "SELECT heartbeat_at, running, document FROM service_state WHERE id = 1"
            ).fetchone()
        except sqlite3.OperationalError:  # a queue from before the heartbeat existed
            row = None
    finally:
        db.close()
    file_bytes = sum(
        Path(f"{path}{suffix}").stat().st_size
        for suffix in ("", "-wal")
        if Path(f"{path}{suffix}").exists()
    )
    return Snapshot(
        counters=counters,
        oldest_queued_at=oldest[0] if oldest else None,
        file_bytes=file_bytes,
        quarantined=quarantined[0] if quarantined else None,
        heartbeat_at=row[0] if row else None,
        running=bool(row[1]) if row else False,
        service=orjson.loads(row[2]) if row else {},
    )
