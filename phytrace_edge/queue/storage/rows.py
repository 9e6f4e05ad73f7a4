"""SQL on the ``events`` table that keeps the counters exact: insert and delete rows,
and measure how much of the file is in use. Each runs in the caller's transaction."""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from typing import NamedTuple

from phytrace_edge.queue.storage.database import bump_counters

MAX_ID = 2**63 - 1


class NewRow(NamedTuple):
    """One event on its way into the ``events`` table (its id comes with the insert)."""

    event_id: str
    important: int  # 1: never thinned, sent first of its age band
    queued_at: float
    codec: int
    dict_id: int | None
    json_size: int  # of the event's JSON, before compression
    body: bytes


class RowSize(NamedTuple):
    """What a row weighs, read before a claim reads any body."""

    id: int
    last_id: int  # > id for a frame of events
    events: int  # the column ``count``
    json_size: int
    queued_at: float


class StoredRow(NamedTuple):
    """A row as a claim reads it: one event, or a frame of ``count`` events."""

    id: int
    last_id: int
    events: int  # the column ``count``
    queued_at: float
    event_id: str
    codec: int
    dict_id: int | None
    body: bytes


class ThinnedRow(NamedTuple):
    """A row as thinning reads it: whether it may be halved, and its events."""

    id: int
    last_id: int
    events: int  # the column ``count``
    important: int
    thin_level: int
    queued_at: float
    newest_at: float | None  # a frame's newest event (its TTL clock); None: one event
    codec: int
    dict_id: int | None
    body: bytes


class FramedRow(NamedTuple):
    """A single-event row as sealing reads it, to pack it into a frame."""

    queued_at: float
    event_id: str
    codec: int
    dict_id: int | None
    body: bytes


STORED_COLUMNS = "id, last_id, count, queued_at, event_id, codec, dict_id, body"
SIZE_COLUMNS = "id, last_id, count, json_size, queued_at"
THINNED_COLUMNS = (
    "id, last_id, count, important, thin_level, queued_at, newest_at, codec, dict_id, body"
)
FRAMED_COLUMNS = "queued_at, event_id, codec, dict_id, body"


def insert_rows(cursor: sqlite3.Cursor, rows: Sequence[NewRow], **counters: int) -> None:
    """Insert rows with ids from next_id, keeping depth and stored_bytes exact, and add
    ``counters``."""
    next_id = cursor.execute("SELECT value FROM counters WHERE name = 'next_id'").fetchone()[0]
    cursor.executemany(
        "INSERT INTO events(id, last_id, event_id, important, queued_at, codec, dict_id, "
        "json_size, body) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
        [(next_id + offset, next_id + offset, *row) for offset, row in enumerate(rows)],
    )
    bump_counters(
        cursor,
        next_id=len(rows),
        depth=len(rows),
        stored_bytes=sum(len(row.body) for row in rows),
        **counters,
    )


def delete_range(cursor: sqlite3.Cursor, first_id: int, last_id: int) -> int:
    """Delete the rows wholly within ids first_id..last_id, keeping depth and
    stored_bytes exact; the number of events they held. (A frame sealed after a lease
    ran out may reach past the lease's range: it stays, and is sent again.)"""
    span = (first_id, last_id, last_id)
    count, size = cursor.execute(
        "SELECT coalesce(sum(count), 0), coalesce(sum(length(body)), 0) FROM events "
        "WHERE id BETWEEN ? AND ? AND last_id <= ?",
        span,
    ).fetchone()
    cursor.execute("DELETE FROM events WHERE id BETWEEN ? AND ? AND last_id <= ?", span)
    bump_counters(cursor, depth=-count, stored_bytes=-size)
    return int(count)


def depth_and_used_bytes(cursor: sqlite3.Cursor, page_size: int) -> tuple[int, int]:
    """Events queued, and bytes of the database's pages in use (free pages excluded)."""
    depth, pages, free = cursor.execute(
        "SELECT (SELECT value FROM counters WHERE name = 'depth'), page_count, freelist_count "
        "FROM pragma_page_count(), pragma_freelist_count()"
    ).fetchone()
    return int(depth or 0), int((pages - free) * page_size)
