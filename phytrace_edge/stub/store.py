"""The stub's record of what PhyCloud received, in its own SQLite file.

sqlite-utils creates the schema and answers the queries; the ingest path inserts with
one plain ``executemany`` (sqlite-utils' per-row insert is several times slower).
``INSERT OR IGNORE`` on the unique ``event_id`` is the deduplication: a replayed event
is acknowledged and counted as a duplicate, not stored twice. A restarted stub reopens
the same file and keeps its record.

Each part of an ``incident`` event is also noted in ``incident_parts`` (incident id,
part, its summary and the ``seq`` of its event), in the same transaction, so that the
page's list of incidents never reads the parts' samples; one incident's samples are
read from the events when it is asked for, per topic, within ``MAX_INCIDENT_BYTES``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import orjson
import sqlite_utils

from phytrace_edge.stub.incidents import merge, part_row

MAX_INCIDENT_BYTES = 32 * 1024 * 1024  # one incident's samples, as JSON, in one answer


class IncidentTooLarge(Exception):
    """The incident's samples asked for are over ``MAX_INCIDENT_BYTES``."""


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
        self._create_incident_parts()

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
            self._note_incident_parts(conn, events)
            self._bump(
                conn, received=len(events), duplicates=len(events) - stored, **stored_by_source
            )
        return stored, len(events) - stored

    def _create_incident_parts(self) -> None:
        """The table of incident parts; created on a record kept before it existed, it
        is filled from the incidents already stored."""
        table = self.db["incident_parts"]
        existed = table.exists()
        table.create(  # type: ignore[union-attr]
            {
                "incident_id": str,
                "part": int,
                "parts": int,
                "source_id": str,
                "trigger_at": str,
                "summary": str,
                "seq": int,
            },
            pk=("incident_id", "part"),
            if_not_exists=True,
        )
        table.create_index(["trigger_at"], if_not_exists=True)  # type: ignore[union-attr]
        if existed:
            return
        rows = self.db.execute(
            'SELECT body FROM events WHERE body LIKE \'%"event_type":"incident"%\''
        )
        with self.db.conn as conn:
            self._note_incident_parts(conn, (orjson.loads(body) for (body,) in rows))

    @staticmethod
    def _note_incident_parts(conn: Any, events: Any) -> None:
        """Note the incident parts among ``events`` (already stored); a part noted
        before (a replay) stays as it was."""
        rows = [row for row in map(part_row, events) if row is not None]
        if rows:
            conn.executemany(
                "INSERT OR IGNORE INTO incident_parts"
                "(incident_id, part, parts, source_id, trigger_at, summary, seq) "
                "SELECT ?, ?, ?, ?, ?, ?, seq FROM events WHERE event_id = ?",
                rows,
            )

    def incidents(self, source_id: str | None, limit: int) -> list[dict[str, Any]]:
        """The newest ``limit`` incidents (by their trigger's time), newest first, each
        merged from the parts received so far (no samples: their counts)."""
        rows = self.db.execute(
            "SELECT incident_id, source_id, part, parts, summary, trigger_at FROM incident_parts "
            "WHERE incident_id IN (SELECT incident_id FROM incident_parts "
            "WHERE ?1 IS NULL OR source_id = ?1 GROUP BY incident_id "
            "ORDER BY max(trigger_at) DESC, incident_id DESC LIMIT ?2)",
            [source_id or None, limit],
        ).fetchall()
        by_id: dict[str, list[Any]] = {}
        for row in rows:
            by_id.setdefault(row[0], []).append(row)
        newest_first = sorted(
            by_id.values(), key=lambda parts: (max(p[5] for p in parts), parts[0][0]), reverse=True
        )
        return [merge(p[0][0], p[0][1], [(r[2], r[3], r[4]) for r in p]) for p in newest_first]

    def incident(self, incident_id: str, topics: list[str]) -> dict[str, Any] | None:
        """One incident: its entry of :meth:`incidents` and ``samples``, the received
        parts' samples joined per topic in part order, which is time order (parts slice
        the window in time), only of ``topics`` when given.
        None for an unknown id; IncidentTooLarge beyond ``MAX_INCIDENT_BYTES``."""
        parts = self.db.execute(
            "SELECT source_id, part, parts, summary FROM incident_parts WHERE incident_id = ?",
            [incident_id],
        ).fetchall()
        if not parts:
            return None
        entry = merge(incident_id, parts[0][0], [(p[1], p[2], p[3]) for p in parts])
        rows = self.db.execute(
            "SELECT s.key, s.value FROM incident_parts p JOIN events e ON e.seq = p.seq, "
            "json_each(e.body, '$.incident.samples') s WHERE p.incident_id = ?1 "
            "AND (?2 = '[]' OR s.key IN (SELECT value FROM json_each(?2))) ORDER BY p.part",
            [incident_id, orjson.dumps(topics).decode()],
        )
        samples: dict[str, list[Any]] = {}
        size = 0
        for topic, value in rows:
            size += len(value)
            if size > MAX_INCIDENT_BYTES:
                raise IncidentTooLarge(f"the samples asked for are over {MAX_INCIDENT_BYTES} bytes")
            samples.setdefault(topic, []).extend(orjson.loads(value))
        return {**entry, "samples": dict(sorted(samples.items()))}

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
