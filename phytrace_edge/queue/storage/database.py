"""The queue file's one connection: its lock, write transactions, counters, and the
mapping of every SQLite error to the queue error that tells the operator what to do.

Every module of ``queue/`` reaches SQLite through a ``Database``; nothing outside
``queue/`` does. Counters (depth, stored bytes, drops by reason, ...) live in a table
written in the same transaction as the change they count, so they are exact. A count
that cannot be written because the disk is full is kept in memory and written with the
next transaction that commits; it is forgotten only once that commit succeeded.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import threading
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

from phytrace_edge.errors import QueueDamagedError, QueueError, QueueFullError
from phytrace_edge.queue.space.reserve import SpaceReserve
from phytrace_edge.queue.storage.recovery import connect, mark_damaged
from phytrace_edge.queue.storage.sqlite_errors import queue_error

T = TypeVar("T")
_NORMAL = 1  # PRAGMA synchronous: 0 OFF, 1 NORMAL, 2 FULL, 3 EXTRA
CACHE_KIB = 2000  # SQLite's page cache (its default): the file is in the OS's cache anyway


def configure(connection: sqlite3.Connection, sync: str) -> None:
    """The queue's connection settings (QUEUE_SYNC is ``full`` or ``normal``)."""
    connection.execute(f"PRAGMA synchronous = {'FULL' if sync == 'full' else 'NORMAL'}")
    connection.execute("PRAGMA shrink_memory")  # what the check at open read
    configure_memory(connection)


def configure_memory(connection: sqlite3.Connection) -> None:
    """Cache and delete settings, for every connection to the queue."""
    connection.execute(f"PRAGMA cache_size = -{CACHE_KIB}")
    # Some builds zero every freed page, so that an ack writes every page it frees (an
    # ack of 50 plain events: 239 KB of WAL, against 33 KB with FAST, which clears only
    # pages written anyway). That matters on a full disk and for flash wear; VACUUM
    # clears the rest.
    connection.execute("PRAGMA secure_delete = FAST")


class Database:
    """One SQLite connection shared by the queue's threads, serialised by a lock."""

    def __init__(
        self, connection: sqlite3.Connection, path: Path, reserve: SpaceReserve | None = None
    ) -> None:
        self.path = path
        self.connection = connection
        self.reserve = reserve
        self.lock = threading.RLock()
        self.page_size = int(connection.execute("PRAGMA page_size").fetchone()[0])
        self.synchronous = int(connection.execute("PRAGMA synchronous").fetchone()[0])
        self._deferred: Counter[str] = Counter()
        # its own lock: a count may be deferred while another thread holds ``lock``
        self._deferred_lock = threading.Lock()

    def write(self, body: Callable[[sqlite3.Cursor], T], durable: bool = True) -> T:
        """Run ``body`` in a write transaction that must happen even on a full disk (a
        delete, a claim, a count). When the disk is full, the WAL is checkpointed and
        truncated first (its pages move into the file, and its own bytes go back to
        the disk); failing that, the space reserve is given up (see ``reserve``)."""
        for last_try in (False, False, True):
            try:
                with self.transaction(durable) as cursor:
                    return body(cursor)
            except QueueFullError:
                if last_try or not self._make_room():
                    raise
        raise AssertionError("the last try returns or raises")

    def _make_room(self) -> bool:
        """Checkpoint and truncate the WAL; else release the reserve and do so. False
        when neither could be done."""
        with contextlib.suppress(QueueError):
            busy, _, _ = self.read("PRAGMA wal_checkpoint(TRUNCATE)")[0]
            if not busy and self._wal_bytes() == 0:
                return True
        if self.reserve is None or not self.reserve.release():
            return False
        with contextlib.suppress(QueueError):
            self.read("PRAGMA wal_checkpoint(TRUNCATE)")
        return True

    def size_wal(self, limit: int) -> None:
        """Keep the WAL near ``limit`` bytes, and checkpoint often enough that moving it
        into the database never needs more room than the full-disk reserve holds."""
        self.execute(f"PRAGMA journal_size_limit = {limit}")
        room = min(limit, self.reserve.size if self.reserve else limit)
        self.execute(f"PRAGMA wal_autocheckpoint = {max(16, room // self.page_size // 2)}")

    def bound_wal(self, limit: int) -> None:
        """Truncate the WAL once it outgrows ``limit`` bytes. (SQLite's autocheckpoint
        copies pages back but leaves the WAL file at its largest.)"""
        if self._wal_bytes() > limit:
            with contextlib.suppress(QueueError):
                self.execute("PRAGMA wal_checkpoint(TRUNCATE)")

    def _wal_bytes(self) -> int:
        try:
            return os.stat(f"{self.path}-wal").st_size  # noqa: PTH116 - on the hot path
        except FileNotFoundError:
            return 0

    @contextlib.contextmanager
    def transaction(
        self, durable: bool = True, after_commit: Callable[[], None] | None = None
    ) -> Iterator[sqlite3.Cursor]:
        """A write transaction (BEGIN IMMEDIATE); SQLite errors become queue errors.

        ``durable=False`` commits at ``synchronous=NORMAL``: atomic, and safe against
        a crash of the process, but a power cut may lose it; the next durable commit's
        fsync covers it too. For claims and acks, whose loss only means a resend.
        ``after_commit`` runs after the commit, still under the lock, so that a reader
        holding the lock never sees the change without what the caller records of it."""
        with self.lock:
            cursor = self.connection.cursor()
            relaxed = not durable and self.synchronous > _NORMAL
            try:
                if relaxed:
                    cursor.execute("PRAGMA synchronous = NORMAL")
                cursor.execute("BEGIN IMMEDIATE")
                yield cursor
                with self._deferred_lock:
                    deferred = dict(self._deferred)
                bump_counters(cursor, **deferred)
                cursor.execute("COMMIT")
                with self._deferred_lock:
                    self._deferred.subtract(deferred)
                    self._deferred = +self._deferred  # drop the zeros
                if after_commit is not None:
                    after_commit()
            except BaseException as exc:
                if self.connection.in_transaction:
                    self.connection.rollback()
                if isinstance(exc, sqlite3.Error):
                    raise self._failed(exc) from exc
                raise
            finally:
                if relaxed:
                    self.connection.execute(f"PRAGMA synchronous = {self.synchronous}")

    def read(self, sql: str, params: Sequence[Any] = ()) -> list[Any]:
        """Rows of a read-only query (no write lock)."""
        with self.lock:
            try:
                return self.connection.execute(sql, params).fetchall()
            except sqlite3.Error as exc:
                raise self._failed(exc) from exc

    def execute(self, sql: str) -> None:
        """A statement outside a transaction (a PRAGMA, VACUUM)."""
        with self.lock:
            try:
                self.connection.execute(sql).fetchall()
            except sqlite3.Error as exc:
                raise self._failed(exc) from exc

    def _failed(self, exc: sqlite3.Error) -> QueueError:
        """The queue error for ``exc``; damage is also marked for the next open."""
        error = queue_error(exc, self.path)
        if isinstance(error, QueueDamagedError):
            mark_damaged(self.path, str(exc))
        return error

    def reopen(self, replace_file: Callable[[], None]) -> None:
        """Close the connection, let ``replace_file`` put another file at the path, and
        connect to that (``file_watch``: a deleted queue file copied back)."""
        with self.lock:
            busy_timeout_ms = self.connection.execute("PRAGMA busy_timeout").fetchone()[0]
            self.connection.close()
            replace_file()
            connection = connect(self.path, busy_timeout_ms / 1000)
            connection.execute(f"PRAGMA synchronous = {self.synchronous}")
            configure_memory(connection)
            self.connection = connection

    def defer_counts(self, **deltas: int) -> None:
        """Counts to write with the next transaction that commits (the disk is full)."""
        with self._deferred_lock:
            self._deferred.update(deltas)

    def deferred_counts(self) -> dict[str, int]:
        """Counts not yet written, for ``stats`` to add to what the table says."""
        with self._deferred_lock:
            return dict(self._deferred)

    def counter(self, name: str) -> int:
        rows = self.read("SELECT value FROM counters WHERE name = ?", (name,))
        return int(rows[0][0]) if rows else 0

    def close(self) -> None:
        with self.lock:
            self.connection.close()


def bump_counters(cursor: sqlite3.Cursor, **deltas: int) -> None:
    """Add to counters in one statement, inside the caller's transaction."""
    items = [(name, delta) for name, delta in deltas.items() if delta]
    if items:
        cursor.execute(
            "INSERT INTO counters(name, value) VALUES "  # noqa: S608 - only placeholders join
            + ", ".join("(?, ?)" for _ in items)
            + " ON CONFLICT(name) DO UPDATE SET value = value + excluded.value",
            [part for item in items for part in item],
        )
