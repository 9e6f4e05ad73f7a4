"""The stub's record of what PhyCloud received, in its own SQLite file.

sqlite-utils creates the schema and answers the queries; the ingest path inserts with
one plain ``executemany`` (sqlite-utils' per-row insert is several times slower).
``INSERT OR IGNORE`` on the unique ``event_id`` is the deduplication: a replayed event
is acknowledged and counted as a duplicate, not stored twice. A restarted stub reopens
the same file and keeps its record.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import orjson
import sqlite_utils


class StubStore:
    """Events received by the stub, deduplicated by ``event_id``, and counters."""

    def __init__(self, path: str | Path) -> None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite_utils.Database(path)
        self.db.enable_wal()
        self.db.execute("PRAGMA synchronous = NORMAL")
        self.db["events"].create(  # type: ignore[union-attr]
            {
                "seq": int,
                "event_id": str,
                "source_id": str,
                "captured_at": str,
                "received_at": float,
                "body": str,
            },
            pk="seq",
            if_not_exists=True,
        )
        self.db["events"].create_index(["event_id"], unique=True, if_not_exists=True)  # type: ignore[union-attr]
        self.db["events"].create_index(["source_id", "seq"], if_not_exists=True)  # type: ignore[union-attr]
        self.db["counters"].create({"name": str, "value": int}, pk="name", if_not_exists=True)  # type: ignore[union-attr]

    def record(self, events: list[dict[str, Any]]) -> tuple[int, int]:
        """Store a batch of valid events; (newly stored, duplicates)."""
        now = time.time()
        by_source: dict[str, list[tuple[str, str, str, float, str]]] = {}
        for e in events:
            source = str(e.get("source_id"))
            by_source.setdefault(source, []).append(
                (
                    str(e.get("event_id")),
                    source,
                    str(e.get("captured_at")),
                    now,
                    orjson.dumps(e).decode(),
                )
            )
        conn = self.db.conn
        stored_by_source = {}
        with conn:
            for source, rows in by_source.items():
                stored_by_source[f"source:{source}"] = conn.executemany(
                    "INSERT OR IGNORE INTO events"
                    "(event_id, source_id, captured_at, received_at, body) VALUES (?, ?, ?, ?, ?)",
                    rows,
                ).rowcount
            stored = sum(stored_by_source.values())
            self._bump(
                conn, received=len(events), duplicates=len(events) - stored, **stored_by_source
            )
        return stored, len(events) - stored

    def count_rejected(self, count: int) -> None:
        with self.db.conn as conn:
            self._bump(conn, rejected=count)

    @staticmethod
    def _bump(conn: Any, **deltas: int) -> None:
        conn.executemany(
            "INSERT INTO counters(name, value) VALUES (?, ?) "
            "ON CONFLICT(name) DO UPDATE SET value = value + excluded.value",
            [(name, delta) for name, delta in deltas.items() if delta],
        )

    def stats(self) -> dict[str, Any]:
        """``{"received", "unique", "duplicates", "rejected", "by_source"}``."""
        counters = {row["name"]: row["value"] for row in self.db["counters"].rows}
        by_source = {k[7:]: v for k, v in counters.items() if k.startswith("source:")}
        return {
            "received": counters.get("received", 0),
            "unique": sum(by_source.values()),
            "duplicates": counters.get("duplicates", 0),
            "rejected": counters.get("rejected", 0),
            "by_source": by_source,
        }

    def events(self, source_id: str | None, after: int, limit: int) -> tuple[list[Any], int]:
        """Stored events oldest first after cursor ``after``; (events, next cursor)."""
        where = "seq > ?"
        params: list[Any] = [after]
        if source_id:
            where += " AND source_id = ?"
            params.append(source_id)
        rows = list(
            self.db["events"].rows_where(
                where, params, order_by="seq", limit=limit, select="seq, body"
            )
        )
        next_after = rows[-1]["seq"] if rows else after
        return [orjson.loads(row["body"]) for row in rows], next_after

    def close(self) -> None:
        self.db.close()
