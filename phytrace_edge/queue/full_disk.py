"""What the queue does on a full volume: the rules that keep it able to drain.

Making room for new events never touches the full-disk reserve (``reserve``): it is
kept for what lets the queue drain (claims, acks), or new events would take it at once.
Once it is gone, new events may only fill pages the file already has: were they to grow
it, the next ack could find no room for its own pages, and the queue could neither
drain nor take events until someone freed space.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.caps import ROW_OVERHEAD_BYTES, drop_oldest
from phytrace_edge.queue.database import Database, bump_counters

log = logging.getLogger(__name__)

REPORT_EVERY_S = 60.0


class FullDisk:
    """The full-disk rules of one queue, and its once-a-minute report of refused events."""

    def __init__(self, db: Database, wal_reserve: int) -> None:
        self._db = db
        self._wal_reserve = wal_reserve
        self._next_report = 0.0
        self._refused_since_report = 0

    def refuses(self, sizes: list[int]) -> bool:
        """New rows of these encoded sizes must not be written: the reserve is gone
        and they would grow the file."""
        reserve = self._db.reserve
        if reserve is None or reserve.held():
            return False
        free_pages = self._db.read("PRAGMA freelist_count")[0][0]
        needed = 2 * (sum(sizes) + ROW_OVERHEAD_BYTES * len(sizes))
        return bool(free_pages * self._db.page_size < needed)

    def has_room_to_seal(self, path: Path) -> bool:
        """A frame's pages are written before its rows' are freed, and a checkpoint may
        grow the file for them: on a nearly full volume that would eat the room acks
        need, so sealing waits for twice the WAL's share to be free."""
        free = os.statvfs(path.parent)
        return free.f_bavail * free.f_frsize >= 2 * self._wal_reserve

    def evict_oldest(self, count: int, now: float) -> bool:
        """Drop the ``count`` oldest events (not those being sent) as ``disk_full``, to
        keep new ones (QUEUE_ON_FULL=drop_oldest or thin); False when none could go."""
        try:
            with self._db.transaction() as cursor:
                return drop_oldest(cursor, count, "disk_full", now) > 0
        except QueueError:
            return False

    def refused(self, path: Path, count: int) -> None:
        """New events dropped at once: counted (``_count``) and logged (``_report``)."""
        self._count(count)
        self._report(path, count)

    def _count(self, count: int) -> None:
        """Count events put and dropped at once: in the database if a transaction still
        fits, else in memory until one does."""
        counts = {"drop:disk_full": count, "queued_total": count}
        try:
            with self._db.transaction() as cursor:
                bump_counters(cursor, **counts)
        except QueueError:
            self._db.defer_counts(**counts)

    def _report(self, path: Path, count: int) -> None:
        """Log refused events once a minute, not per event."""
        self._refused_since_report += count
        if time.monotonic() < self._next_report:
            return
        self._next_report = time.monotonic() + REPORT_EVERY_S
        log.error(
            "queue %s: disk full, %d new event(s) dropped since the last report - "
            "free space on the volume or lower QUEUE_MAX_BYTES",
            path,
            self._refused_since_report,
        )
        self._refused_since_report = 0
