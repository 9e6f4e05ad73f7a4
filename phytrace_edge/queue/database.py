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
import sqlite3
import threading
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

from phytrace_edge.errors import QueueFullError
from phytrace_edge.queue.reserve import SpaceReserve
from phytrace_edge.queue.sqlite_errors import queue_error

T = TypeVar("T")


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
        self._deferred: Counter[str] = Counter()

    def write(self, body: Callable[[sqlite3.Cursor], T]) -> T:
        """Run ``body`` in a write transaction that must happen even on a full disk (a
        delete, a claim, a count): the first time the disk is full, the space reserve
        is given up and ``body`` runs again (see ``reserve``)."""
        try:
            with self.transaction() as cursor:
                return body(cursor)
        except QueueFullError:
            if self.reserve is None or not self.reserve.release():
                raise
        with self.transaction() as cursor:
            return body(cursor)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Cursor]:
        """A write transaction (BEGIN IMMEDIATE); SQLite errors become queue errors."""
        with self.lock:
            cursor = self.connection.cursor()
            try:
                cursor.execute("BEGIN IMMEDIATE")
                yield cursor
                deferred = dict(self._deferred)
                bump_counters(cursor, **deferred)
                cursor.execute("COMMIT")
                self._deferred.subtract(deferred)
                self._deferred = +self._deferred  # drop the zeros
            except BaseException as exc:
                if self.connection.in_transaction:
                    self.connection.rollback()
                if isinstance(exc, sqlite3.Error):
                    raise queue_error(exc, self.path) from exc
                raise

    def read(self, sql: str, params: Sequence[Any] = ()) -> list[Any]:
        """Rows of a read-only query (no write lock)."""
        with self.lock:
            try:
                return self.connection.execute(sql, params).fetchall()
            except sqlite3.Error as exc:
                raise queue_error(exc, self.path) from exc

    def execute(self, sql: str) -> None:
        """A statement outside a transaction (a PRAGMA, VACUUM)."""
        with self.lock:
            try:
                self.connection.execute(sql).fetchall()
            except sqlite3.Error as exc:
                raise queue_error(exc, self.path) from exc

    def defer_counts(self, **deltas: int) -> None:
        """Counts to write with the next transaction that commits (the disk is full)."""
        with self.lock:
            self._deferred.update(deltas)

    def deferred_counts(self) -> dict[str, int]:
        """Counts not yet written, for ``stats`` to add to what the table says."""
        with self.lock:
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
