"""Periodic upkeep of the queue file: TTL expiry and giving space back to the disk."""

from __future__ import annotations

import sqlite3

from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.storage.database import Database, bump_counters
from phytrace_edge.queue.storage.rows import delete_range
from phytrace_edge.units import MIB

EXPIRE_CHUNK = 1000
RECLAIM_MIN_BYTES = 1 * MIB


def expire(db: Database, cutoff: float, now: float) -> int:
    """Delete events queued before ``cutoff`` (not those being sent); the count."""

    def delete_expired(cursor: sqlite3.Cursor) -> int:
        expired = 0
        # a frame expires with its newest event: never before the TTL
        ages = "id, last_id, coalesce(newest_at, queued_at)"
        for chunk in leases.unleased(cursor, now, ages, EXPIRE_CHUNK):
            rows = chunk.rows
            fresh_at = next((i for i, (_, _, age) in enumerate(rows) if age >= cutoff), len(rows))
            if fresh_at:
                _, last_expired, _ = rows[fresh_at - 1]
                expired += delete_range(cursor, chunk.low, last_expired)
            if fresh_at < len(rows):
                break  # ids grow with time: the first fresh row ends the expired prefix
        bump_counters(cursor, **{"drop:ttl": expired})
        return expired

    return db.write(delete_expired)


def reclaim_space(db: Database, force: bool = False) -> None:
    """Give space back to the file system once most of the file is free pages (a
    backlog has drained): VACUUM then rewrites only the few live rows, which is quick.
    Free pages of a partly drained queue are left for new events to reuse. The WAL is
    truncated either way."""
    pages, free = db.read(
        "SELECT page_count, freelist_count FROM pragma_page_count(), pragma_freelist_count()"
    )[0]
    mostly_free = free * db.page_size >= RECLAIM_MIN_BYTES and free > pages - free
    if force or mostly_free:
        db.execute("VACUUM")
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
