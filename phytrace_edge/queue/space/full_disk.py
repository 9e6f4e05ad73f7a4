"""What the queue does on a full volume: the rules that keep it able to drain.

"Full" is judged by the volume's real free space (``statvfs``, via ``VolumeSpace``), not
by whether the reserve file is there: a reserve someone removed on a roomy disk is made
again at once, and nothing is refused or evicted for it. Queued events are evicted
(``evict_oldest``, counted ``disk_full``) only after SQLite reported SQLITE_FULL or the
volume really has no room; a write that failed for another reason (read-only, an I/O
error, a moved file) never evicts anything. A volume that cannot be looked at (its
folder moved, removed or unmounted) is "unknown": nothing is sealed, refused or evicted
for it, and nothing raises.

Making room for new events never touches the full-disk reserve (``reserve``): it is
kept for what lets the queue drain (claims, acks), or new events would take it at once.
Once it is gone and the volume has no room, new events may only fill pages the file
already has: were they to grow it, the next ack could find no room for its own pages,
and the queue could neither drain nor take events until someone freed space.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.space.caps import (
    LOOK_EVERY_S,
    ROW_OVERHEAD_BYTES,
    VolumeSpace,
    drop_oldest,
)
from phytrace_edge.queue.space.volume import wal_share
from phytrace_edge.queue.storage.database import Database, bump_counters

log = logging.getLogger(__name__)

REPORT_EVERY_S = 60.0
EVICT_ROUNDS = 8  # evictions that double each time: up to 255x the first


class FullDisk:
    """The full-disk rules of one queue, and its once-a-minute report of refused events."""

    def __init__(self, db: Database, volume: VolumeSpace) -> None:
        self._db = db
        self.volume = volume
        self._next_report = 0.0
        self._refused_since_report = 0
        self._restore_after = 0.0  # monotonic: the reserve is not tried again before

    def refuses(self, sizes: list[int]) -> bool:
        """New rows of these encoded sizes must not be written: the volume is really
        full (``statvfs``), the reserve is gone, and they would grow the file. A missing
        reserve on a volume with room is made again instead."""
        reserve = self._db.reserve
        if reserve is None or reserve.held():
            return False
        needed = self._needed(sizes)
        volume = self.volume.look()
        if volume is None:
            return False  # unknown (the folder is gone): SQLite says whether they fit
        if volume.free >= 2 * reserve.size + needed:
            self.restore_reserve()  # not a full disk: the reserve comes back now
            return False
        return self._free_bytes() < needed

    def _needed(self, sizes: list[int]) -> int:
        """Free bytes in the file that new rows of these sizes need (twice theirs: the
        WAL's copy of each page, then the page)."""
        return 2 * (sum(sizes) + ROW_OVERHEAD_BYTES * len(sizes))

    def _free_bytes(self) -> int:
        """The bytes of the file's free pages."""
        return int(self._db.read("PRAGMA freelist_count")[0][0]) * self._db.page_size

    def make_room(self, sizes: list[int], count: int, now: float) -> bool:
        """Evict the oldest events (``evict_oldest``) so that new rows of these sizes
        can be written; True when they may be tried again. On a volume with no room and
        the reserve gone, until they fit in the file's free pages (``refuses``), ``count``
        and then twice as many each round, and nothing at all when even the whole queue
        would not free enough: old events evicted for new ones that are refused anyway
        are lost for nothing. Otherwise (SQLite itself found the disk full) ``count``."""
        if not self.refuses(sizes):
            return self.evict_oldest(count, now)
        if self._db.counter("stored_bytes") + self._free_bytes() < self._needed(sizes):
            return False
        for _ in range(EVICT_ROUNDS):
            if not self.evict_oldest(count, now):
                return False
            if not self.refuses(sizes):
                return True
            count *= 2
        return False

    def restore_reserve(self) -> bool:
        """Make the reserve again when it is missing and the volume has room for it
        twice (tried at most once every LOOK_EVERY_S); True when it is held."""
        reserve = self._db.reserve
        if reserve is None or reserve.held():
            return True
        if time.monotonic() < self._restore_after:
            return False
        self._restore_after = time.monotonic() + LOOK_EVERY_S
        lacked_room = reserve.lacked_room
        if not reserve.restore():
            return False
        if lacked_room:
            log.info("queue %s: the disk has room again; the reserve is back", self._db.path)
        else:
            log.warning(
                "queue %s: its full-disk reserve %s was missing (removed?); made it again",
                self._db.path,
                reserve.path,
            )
        return True

    def has_room_to_seal(self) -> bool:
        """A frame's pages are written before its rows' are freed, and a checkpoint may
        grow the file for them: on a nearly full volume that would eat the room acks
        need, so sealing waits for twice the WAL's share (of the effective cap) to be
        free. Never on a volume that cannot be looked at."""
        volume = self.volume.look()
        if volume is None:
            return False
        return volume.free >= 2 * wal_share(self.volume.cap().files)

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
