"""QueueStore: the durable hand-off between build and ship, one SQLite file in WAL mode.

Build appends (``put``/``put_many``); ship takes the oldest events under a lease
(``claim_batch``), sends them, and deletes them only after PhyCloud accepted them
(``ack``), or gives them back (``release``). A lease is a row in the database, so two
processes (the service and an operator's ``drain``) never send the same events at the
same time, and a crashed sender's lease expires and its events come back.

Durability: ``put`` returns after its transaction committed; with QUEUE_SYNC=full
(the default) that includes an fsync of the WAL, so an acknowledged event survives a
kill -9 and a power loss. Grouped puts share one fsync (group commit).

Every event that leaves the queue other than by ``ack`` is counted by reason in the
``counters`` table: ``drop:cap_bytes``, ``drop:cap_events`` (caps), ``drop:ttl``
(expired), ``drop:disk_full`` (SQLITE_FULL), ``drop:rejected`` (dead-lettered).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sqlite3
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from phytrace_edge.config import MIB, format_bytes
from phytrace_edge.errors import QueueError, QueueFullError
from phytrace_edge.queue.codecs import Codecs, Encoded, packaged_dictionary
from phytrace_edge.queue.migrate import migrate
from phytrace_edge.queue.records import (
    Batch,
    DeadLetter,
    PutResult,
    QueuedEvent,
    QueueLimits,
    QueueStats,
)
from phytrace_edge.queue.recovery import open_checked, queue_error

log = logging.getLogger(__name__)

DEFAULT_LEASE_S = 60.0
DEFAULT_BUSY_TIMEOUT_S = 5.0
MAX_ID = 2**63 - 1
ROW_OVERHEAD_BYTES = 96  # event_id, numbers, record and cell headers of one row
PAGE_FILL = 1.15  # B-tree pages are not full: bytes on disk per byte stored
WAL_RESERVE_MAX = 4 * MIB
RECLAIM_MIN_BYTES = 1 * MIB
EXPIRE_CHUNK = 1000
RECHECK_EVERY = 64
MAX_DROP_ROUNDS = 8
MEASURE_FOOTPRINT_AFTER = 32  # events, before which the footprint is only estimated


@dataclass
class _RoomEstimate:
    """Whether a put surely fits under the caps without asking SQLite: the last
    measured usage plus twice what was added since (rows cost more than their bodies)
    must stay under 90% of each cap, and a fresh measurement is taken every
    ``RECHECK_EVERY`` puts. Near a cap every put measures."""

    data_cap: int
    max_events: int | None
    depth: int = 0
    used: int = 0
    puts: int = RECHECK_EVERY  # measure on the first put

    def is_certain(self, events: int, body_bytes: int) -> bool:
        if self.puts >= RECHECK_EVERY:
            return False
        fits_bytes = (
            self.used + 2 * (body_bytes + ROW_OVERHEAD_BYTES * events) <= 0.9 * self.data_cap
        )
        fits_events = self.max_events is None or self.depth + events <= 0.9 * self.max_events
        return fits_bytes and fits_events

    def added(self, events: int, body_bytes: int) -> None:
        self.depth += events
        self.used += 2 * (body_bytes + ROW_OVERHEAD_BYTES * events)
        self.puts += 1

    def measured(self, depth: int, used: int) -> None:
        self.depth, self.used, self.puts = depth, used, 0


@dataclass
class _Pending:
    """Drops that could not be written because the disk was full; flushed later."""

    drops: Counter[str] = field(default_factory=Counter)


class QueueStore:
    """The queue database. Thread-safe: one connection, serialised by a lock."""

    def __init__(
        self,
        connection: sqlite3.Connection,
        path: Path,
        *,
        limits: QueueLimits,
        compression: str = "zstd",
        clock: Callable[[], float] = time.time,
        lease_s: float = DEFAULT_LEASE_S,
    ) -> None:
        self.path = path
        self._wal_path = f"{path}-wal"
        self.limits = limits
        self.lease_s = lease_s
        self._db = connection
        self._clock = clock
        self._lock = threading.RLock()
        self._owner = uuid.uuid4().hex
        self._pending = _Pending()
        self.codecs = Codecs(compression)
        self._page_size = int(self._db.execute("PRAGMA page_size").fetchone()[0])
        self._wal_reserve = min(WAL_RESERVE_MAX, limits.max_bytes // 8)
        self._room = _RoomEstimate(limits.max_bytes - self._wal_reserve, limits.max_events)
        self._db.execute(f"PRAGMA journal_size_limit = {self._wal_reserve}")
        self._db.execute(
            f"PRAGMA wal_autocheckpoint = {max(16, self._wal_reserve // self._page_size // 2)}"
        )
        self._load_dictionaries()

    # ------------------------------------------------------------------ opening

    @classmethod
    def open(
        cls,
        path: str | Path,
        *,
        limits: QueueLimits,
        compression: str = "zstd",
        sync: str = "full",
        clock: Callable[[], float] = time.time,
        lease_s: float = DEFAULT_LEASE_S,
        busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S,
    ) -> QueueStore:
        """Open (creating, checking, migrating) the queue at ``path``.

        A corrupt or non-SQLite file is moved aside and a fresh queue started (see
        ``recovery``); the store remembers the moved file for ``stats``.
        """
        path = Path(path)
        connection, quarantined = open_checked(path, busy_timeout_s)
        connection.execute(f"PRAGMA synchronous = {'FULL' if sync == 'full' else 'NORMAL'}")
        connection.execute("PRAGMA cache_size = -8000")  # 8 MiB, whatever the backlog
        migrate(connection)
        store = cls(
            connection, path, limits=limits, compression=compression, clock=clock, lease_s=lease_s
        )
        if quarantined is not None:
            with store.transaction() as cursor:
                cursor.execute(
                    "INSERT OR REPLACE INTO meta(key, value) VALUES ('quarantined', ?)",
                    (str(quarantined),),
                )
        store.warn_if_disk_smaller_than_cap()
        return store

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def now(self) -> float:
        """The store's clock (unix seconds); injectable for tests of TTL and leases."""
        return self._clock()

    def __enter__(self) -> QueueStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def warn_if_disk_smaller_than_cap(self) -> None:
        """Log a WARNING when the volume could not hold a full queue."""
        free = os.statvfs(self.path.parent)
        available = free.f_bavail * free.f_frsize + self.file_bytes()
        if available < self.limits.max_bytes:
            log.warning(
                "queue %s: the volume has %s free for the queue but QUEUE_MAX_BYTES is %s; "
                "the disk will fill before the cap - lower QUEUE_MAX_BYTES or free space",
                self.path,
                format_bytes(available),
                format_bytes(self.limits.max_bytes),
            )

    # ------------------------------------------------------------------ transactions

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Cursor]:
        """A write transaction (BEGIN IMMEDIATE); SQLite errors become queue errors."""
        with self._lock:
            cursor = self._db.cursor()
            try:
                cursor.execute("BEGIN IMMEDIATE")
                yield cursor
                self._flush_pending(cursor)
                cursor.execute("COMMIT")
            except BaseException as exc:
                if self._db.in_transaction:
                    self._db.rollback()
                if isinstance(exc, sqlite3.Error):
                    raise queue_error(exc, self.path) from exc
                raise

    def read(self, sql: str, params: Sequence[Any] = ()) -> list[Any]:
        """Rows of a read-only query (no write lock)."""
        with self._lock:
            try:
                return self._db.execute(sql, params).fetchall()
            except sqlite3.Error as exc:
                raise queue_error(exc, self.path) from exc

    def _flush_pending(self, cursor: sqlite3.Cursor) -> None:
        for reason, count in self._pending.drops.items():
            bump_counter(cursor, f"drop:{reason}", count)
        self._pending.drops.clear()

    # ------------------------------------------------------------------ put

    def put(self, event: dict[str, Any]) -> PutResult:
        """Queue one event; returns once it is durable (see module doc)."""
        return self.put_many([event])

    def put_many(self, events: Sequence[dict[str, Any]]) -> PutResult:
        """Queue events in one transaction (group commit). Never raises for a full
        queue or a full disk: what cannot be kept is counted as a drop and logged."""
        rows = [self._encode(event) for event in events]
        if not rows:
            return PutResult(0, 0)
        try:
            return self._insert(rows)
        except QueueFullError:
            if self.limits.on_full == "drop_oldest" and self._evict_oldest(
                max(len(rows), self.stats_counter("depth") // 100), "disk_full"
            ):
                with contextlib.suppress(QueueFullError):
                    return self._insert(rows)
            self._count_drop("disk_full", len(rows))
            log.error(
                "queue %s: disk full, %d new event(s) dropped - free space on the volume or "
                "lower QUEUE_MAX_BYTES",
                self.path,
                len(rows),
            )
            return PutResult(0, len(rows))

    def _encode(self, event: dict[str, Any]) -> tuple[str, int, Encoded]:
        raw = orjson.dumps(event)
        return str(event.get("event_id", "")), len(raw), self.codecs.encode(raw)

    def _insert(self, rows: list[tuple[str, int, Encoded]]) -> PutResult:
        now = self._clock()
        with self.transaction() as cursor:
            accepted = self._make_room(cursor, rows)
            self.insert_rows(
                cursor,
                [(eid, now, e.codec, e.dict_id, size, e.body) for eid, size, e in accepted],
                queued_total=len(accepted),
            )
        self._bound_wal()
        return PutResult(len(accepted), len(rows) - len(accepted))

    @staticmethod
    def insert_rows(
        cursor: sqlite3.Cursor, rows: Sequence[tuple[Any, ...]], **counters: int
    ) -> None:
        """Insert (event_id, queued_at, codec, dict_id, json_size, body) rows with ids
        from next_id, keeping depth and stored_bytes exact, and add ``counters``; in the
        caller's transaction."""
        cursor.executemany(
            "INSERT INTO events(id, event_id, queued_at, codec, dict_id, json_size, body) VALUES "
            "((SELECT value FROM counters WHERE name = 'next_id') + ?, ?, ?, ?, ?, ?, ?)",
            [(offset, *row) for offset, row in enumerate(rows)],
        )
        bump_counters(
            cursor,
            next_id=len(rows),
            depth=len(rows),
            stored_bytes=sum(len(r[5]) for r in rows),
            **counters,
        )

    def _bound_wal(self) -> None:
        """Truncate the WAL once it outgrows its share of the byte cap. (SQLite's
        autocheckpoint copies pages back but leaves the WAL file at its largest.)"""
        with contextlib.suppress(FileNotFoundError):
            if os.stat(self._wal_path).st_size > self._wal_reserve:  # noqa: PTH116 - hot path
                with self._lock, contextlib.suppress(sqlite3.Error):
                    self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()

    def _make_room(
        self, cursor: sqlite3.Cursor, rows: list[tuple[str, int, Encoded]]
    ) -> list[tuple[str, int, Encoded]]:
        """Apply the caps before inserting ``rows``; returns the rows that may go in."""
        incoming = sum(len(e.body) for _, _, e in rows)
        if self._room.is_certain(len(rows), incoming):
            self._room.added(len(rows), incoming)
            return rows
        rows = self._make_room_measured(cursor, rows)
        depth, used = self._depth_and_used_bytes(cursor)
        self._room.measured(depth + len(rows), used + incoming)
        return rows

    def _make_room_measured(
        self, cursor: sqlite3.Cursor, rows: list[tuple[str, int, Encoded]]
    ) -> list[tuple[str, int, Encoded]]:
        limits = self.limits
        depth, used = self._depth_and_used_bytes(cursor)
        per_event = self._bytes_per_event(rows, depth, used)
        data_cap = limits.max_bytes - self._wal_reserve
        under_event_cap = limits.max_events is None or depth + len(rows) <= limits.max_events
        if under_event_cap and used + per_event * len(rows) <= data_cap:
            return rows  # the common case: one query, no drops

        if limits.max_events is not None and depth + len(rows) > limits.max_events:
            excess = depth + len(rows) - limits.max_events
            if limits.on_full == "drop_oldest":
                excess -= self._drop_oldest(cursor, excess, "cap_events")
            if excess > 0:
                bump_counter(cursor, "drop:cap_events", min(excess, len(rows)))
                rows = rows[: max(0, len(rows) - excess)]

        over = self._depth_and_used_bytes(cursor)[1] + per_event * len(rows) - data_cap
        if limits.on_full == "drop_oldest":
            for _ in range(MAX_DROP_ROUNDS):  # deleted rows free whole pages only
                if over <= 0 or not self._drop_oldest(
                    cursor, math.ceil(over / per_event) + 1, "cap_bytes"
                ):
                    break
                over = self._depth_and_used_bytes(cursor)[1] + per_event * len(rows) - data_cap
        if over > 0:  # drop_newest, or everything older is being sent
            keep = max(0, len(rows) - math.ceil(over / per_event))
            bump_counter(cursor, "drop:cap_bytes", len(rows) - keep)
            rows = rows[:keep]
        return rows

    @staticmethod
    def _bytes_per_event(rows: list[tuple[str, int, Encoded]], depth: int, used: int) -> int:
        """Disk bytes one of ``rows`` will take: measured on the queue once it holds
        enough events, else estimated from the rows' sizes."""
        estimate = (
            sum(len(e.body) for _, _, e in rows) / len(rows) + ROW_OVERHEAD_BYTES
        ) * PAGE_FILL
        if depth >= MEASURE_FOOTPRINT_AFTER:
            estimate = max(estimate, used / depth)
        return math.ceil(estimate)

    def _depth_and_used_bytes(self, cursor: sqlite3.Cursor) -> tuple[int, int]:
        """Events queued, and bytes of the database's pages in use (free pages excluded)."""
        depth, pages, free = cursor.execute(
            "SELECT (SELECT value FROM counters WHERE name = 'depth'), page_count, freelist_count "
            "FROM pragma_page_count(), pragma_freelist_count()"
        ).fetchone()
        return int(depth or 0), int((pages - free) * self._page_size)

    # ------------------------------------------------------------------ dropping

    def _drop_oldest(self, cursor: sqlite3.Cursor, count: int, reason: str) -> int:
        """Delete up to ``count`` oldest events not under a lease; counted as ``reason``."""
        dropped = 0
        for low, high in self._free_ranges(cursor):
            if dropped >= count:
                break
            ids = cursor.execute(
                "SELECT id FROM events WHERE id BETWEEN ? AND ? ORDER BY id LIMIT ?",
                (low, high, count - dropped),
            ).fetchall()
            if ids:
                dropped += self._delete_range(cursor, ids[0][0], ids[-1][0])
        if dropped:
            bump_counter(cursor, f"drop:{reason}", dropped)
        return dropped

    def _evict_oldest(self, count: int, reason: str) -> bool:
        try:
            with self.transaction() as cursor:
                return self._drop_oldest(cursor, count, reason) > 0
        except QueueError:
            return False

    def _count_drop(self, reason: str, count: int) -> None:
        try:
            with self.transaction() as cursor:
                bump_counter(cursor, f"drop:{reason}", count)
        except QueueError:
            self._pending.drops[reason] += count  # written with the next transaction

    def _delete_range(self, cursor: sqlite3.Cursor, first_id: int, last_id: int) -> int:
        """Delete rows first_id..last_id, keeping depth and stored_bytes exact."""
        count, size = cursor.execute(
            "SELECT count(*), coalesce(sum(length(body)), 0) FROM events WHERE id BETWEEN ? AND ?",
            (first_id, last_id),
        ).fetchone()
        cursor.execute("DELETE FROM events WHERE id BETWEEN ? AND ?", (first_id, last_id))
        bump_counters(cursor, depth=-count, stored_bytes=-size)
        return int(count)

    # ------------------------------------------------------------------ claim / ack

    def _free_ranges(self, cursor: sqlite3.Cursor) -> list[tuple[int, int]]:
        """Id ranges no live lease covers, oldest first (expired leases are removed)."""
        cursor.execute("DELETE FROM leases WHERE expires_at <= ?", (self._clock(),))
        ranges, low = [], 0
        for first, last in cursor.execute("SELECT first_id, last_id FROM leases ORDER BY first_id"):
            if first > low:
                ranges.append((low, first - 1))
            low = max(low, last + 1)
        ranges.append((low, MAX_ID))
        return ranges

    def claim_batch(self, max_events: int, max_bytes: int) -> Batch | None:
        """Lease the oldest unleased events: at most ``max_events`` and ``max_bytes`` of
        JSON (but always one, however large). None when there is nothing to send."""
        if self.stats_counter("depth") == 0:
            return None
        with self.transaction() as cursor:
            rows: list[Any] = []
            for low, high in self._free_ranges(cursor):
                rows = cursor.execute(
                    "SELECT id, event_id, codec, dict_id, json_size, body FROM events "
                    "WHERE id BETWEEN ? AND ? ORDER BY id LIMIT ?",
                    (low, high, max_events),
                ).fetchall()
                if rows:
                    break
            total, keep = 0, 0
            for _, _, _, _, json_size, _ in rows:
                if keep and total + json_size > max_bytes:
                    break
                total += json_size
                keep += 1
            rows = rows[:keep]
            if not rows:
                return None
            cursor.execute(
                "INSERT INTO leases(first_id, last_id, owner, expires_at) VALUES (?, ?, ?, ?)",
                (rows[0][0], rows[-1][0], self._owner, self._clock() + self.lease_s),
            )
        events = [
            QueuedEvent(row_id, event_id, self.codecs.decode(codec, dict_id, body))
            for row_id, event_id, codec, dict_id, _, body in rows
        ]
        return Batch(rows[0][0], rows[-1][0], self._owner, events)

    def ack(self, batch: Batch, dead_letters: Sequence[DeadLetter] = ()) -> None:
        """PhyCloud has the batch: delete it, moving ``dead_letters`` aside first."""
        now = self._clock()
        with self.transaction() as cursor:
            for dead in dead_letters:
                cursor.execute(
                    "INSERT INTO dead_letters(event_id, queued_at, dead_at, reason, status_code, "
                    "response, codec, dict_id, json_size, body) "
                    "SELECT event_id, queued_at, ?, ?, ?, ?, codec, dict_id, json_size, body "
                    "FROM events WHERE id = ?",
                    (
                        now,
                        dead.reason,
                        dead.status_code,
                        (dead.response or "")[:4096] or None,
                        dead.queue_id,
                    ),
                )
            rejected = len(dead_letters)
            deleted = self._delete_range(cursor, batch.first_id, batch.last_id)
            cursor.execute(
                "DELETE FROM leases WHERE first_id = ? AND owner = ?", (batch.first_id, batch.owner)
            )
            bump_counters(
                cursor,
                acked_total=max(0, deleted - rejected),
                dead_letters=rejected,
                **{"drop:rejected": rejected},
            )

    def release(self, batch: Batch) -> None:
        """Give the batch back unsent: its events are claimable again at once."""
        with self.transaction() as cursor:
            cursor.execute(
                "DELETE FROM leases WHERE first_id = ? AND owner = ?", (batch.first_id, batch.owner)
            )

    def renew(self, batch: Batch) -> bool:
        """Extend the lease while a send is still retrying; False if it had expired
        (another sender may have the events now: send them anyway, PhyCloud dedupes)."""
        with self.transaction() as cursor:
            cursor.execute(
                "UPDATE leases SET expires_at = ? "
                "WHERE first_id = ? AND owner = ? AND expires_at > ?",
                (self._clock() + self.lease_s, batch.first_id, batch.owner, self._clock()),
            )
            return cursor.rowcount == 1

    # ------------------------------------------------------------------ maintenance

    def expire(self) -> int:
        """Delete events older than QUEUE_TTL_S (not those being sent); the count."""
        cutoff = self._clock() - self.limits.ttl_s
        expired = 0
        with self.transaction() as cursor:
            for low, high in self._free_ranges(cursor):
                while True:
                    rows = cursor.execute(
                        "SELECT id, queued_at FROM events WHERE id BETWEEN ? AND ? "
                        "ORDER BY id LIMIT ?",
                        (low, high, EXPIRE_CHUNK),
                    ).fetchall()
                    old = [row_id for row_id, queued_at in rows if queued_at < cutoff]
                    # ids grow with time: the first fresh row ends the expired prefix
                    old = old[: next((i for i, r in enumerate(rows) if r[1] >= cutoff), len(rows))]
                    if not old:
                        break
                    expired += self._delete_range(cursor, old[0], old[-1])
                    low = old[-1] + 1
                    if len(old) < len(rows):
                        break
            if expired:
                bump_counter(cursor, "drop:ttl", expired)
        if expired:
            log.warning("queue %s: %d event(s) older than QUEUE_TTL_S expired", self.path, expired)
        return expired

    def reclaim_space(self, force: bool = False) -> int:
        """Give space back to the file system once most of the file is free pages (a
        backlog has drained): VACUUM then rewrites only the few live rows, which is
        quick. Free pages of a partly drained queue are left for new events to reuse.
        Returns bytes given back."""
        before = self.file_bytes()
        with self._lock:
            pages, free = self._db.execute(
                "SELECT page_count, freelist_count "
                "FROM pragma_page_count(), pragma_freelist_count()"
            ).fetchone()
            free_bytes = free * self._page_size
            mostly_free = free_bytes >= RECLAIM_MIN_BYTES and free > pages - free
            try:
                if force or mostly_free:
                    self._db.execute("VACUUM")
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
            except sqlite3.Error as exc:
                raise queue_error(exc, self.path) from exc
            self._room.puts = RECHECK_EVERY
        return max(0, before - self.file_bytes())

    def maintain(self) -> None:
        """Periodic upkeep: TTL expiry, then space reclaim."""
        self.expire()
        self.reclaim_space()

    # ------------------------------------------------------------------ stats

    def _load_dictionaries(self) -> None:
        for dict_id, content in self.read("SELECT dict_id, content FROM zstd_dictionaries"):
            self.codecs.add_dictionary(dict_id, content)
        if not self.read(
            "SELECT 1 FROM zstd_dictionaries WHERE dict_id = ?", (self.codecs.dict_id,)
        ):
            dict_id, content = packaged_dictionary()
            with self.transaction() as cursor:
                cursor.execute(
                    "INSERT OR IGNORE INTO zstd_dictionaries(dict_id, content, added_at) "
                    "VALUES (?, ?, ?)",
                    (dict_id, content, self._clock()),
                )

    def stats_counter(self, name: str) -> int:
        rows = self.read("SELECT value FROM counters WHERE name = ?", (name,))
        return int(rows[0][0]) if rows else 0

    def backlog(self) -> tuple[int, float | None]:
        """(events queued, when the oldest was queued): two indexed lookups."""
        rows = self.read(
            "SELECT (SELECT value FROM counters WHERE name = 'depth'), "
            "(SELECT queued_at FROM events ORDER BY id LIMIT 1)"
        )
        depth, oldest = rows[0]
        return int(depth or 0), oldest

    def file_bytes(self) -> int:
        """Bytes on disk: the database, its WAL and shared-memory files."""
        total = 0
        for suffix in ("", "-wal", "-shm"):
            with contextlib.suppress(FileNotFoundError):
                total += Path(f"{self.path}{suffix}").stat().st_size
        return total

    def stats(self) -> QueueStats:
        counters = dict(self.read("SELECT name, value FROM counters"))
        oldest = self.read("SELECT queued_at FROM events ORDER BY id LIMIT 1")
        newest = self.read("SELECT queued_at FROM events ORDER BY id DESC LIMIT 1")
        quarantined = self.read("SELECT value FROM meta WHERE key = 'quarantined'")
        return QueueStats(
            path=str(self.path),
            depth=counters.get("depth", 0),
            stored_bytes=counters.get("stored_bytes", 0),
            file_bytes=self.file_bytes(),
            oldest_queued_at=oldest[0][0] if oldest else None,
            newest_queued_at=newest[0][0] if newest else None,
            drops={k[5:]: v for k, v in counters.items() if k.startswith("drop:") and v},
            dead_letters=counters.get("dead_letters", 0),
            queued_total=counters.get("queued_total", 0),
            acked_total=counters.get("acked_total", 0),
            leased=self.read("SELECT count(*) FROM leases WHERE expires_at > ?", (self._clock(),))[
                0
            ][0],
            max_bytes=self.limits.max_bytes,
            quarantined=quarantined[0][0] if quarantined else None,
        )


def bump_counter(cursor: sqlite3.Cursor, name: str, delta: int) -> None:
    """Add ``delta`` to one counter, inside the caller's transaction."""
    bump_counters(cursor, **{name: delta})


def bump_counters(cursor: sqlite3.Cursor, **deltas: int) -> None:
    """Add to several counters in one statement."""
    items = [(name, delta) for name, delta in deltas.items() if delta]
    if items:
        cursor.execute(
            "INSERT INTO counters(name, value) VALUES "  # noqa: S608 - only placeholders join
            + ", ".join("(?, ?)" for _ in items)
            + " ON CONFLICT(name) DO UPDATE SET value = value + excluded.value",
            [part for item in items for part in item],
        )
