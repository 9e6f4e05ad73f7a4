"""The byte and event caps, and what a full queue drops (QUEUE_ON_FULL).

The byte cap is the effective cap (``volume``): QUEUE_MAX_BYTES, or what the volume
can give the queue when that is less, looked at by ``VolumeSpace``. ``Caps.make_room``
runs in the put's transaction: until the put fits, it thins the oldest periodic
history (``thin``, see ``thinning``; then drops the oldest periodic events, and
important ones last), drops the oldest unleased events (``drop_oldest``) or the newest
incoming ones (``drop_newest``), and counts them by reason (``thinned``, ``cap_events``,
and ``cap_bytes``, or ``disk_full`` when the volume set the cap). Asking SQLite how
full the file is costs a query, so most puts are admitted by an estimate that is
certain to be safe.
"""

from __future__ import annotations

import math
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from phytrace_edge.queue.defaults import OnFull
from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.peek import file_bytes
from phytrace_edge.queue.space.thinning import thin_oldest
from phytrace_edge.queue.space.volume import (
    LIMIT_VOLUME,
    Cap,
    Volume,
    effective_cap,
    look_at,
    wal_share,
)
from phytrace_edge.queue.storage.database import bump_counters
from phytrace_edge.queue.storage.rows import delete_range, depth_and_used_bytes

ROW_OVERHEAD_BYTES = 96  # event_id, numbers, record and cell headers of one row
PAGE_FILL = 1.15  # B-tree pages are not full: bytes on disk per byte stored
RECHECK_EVERY = 64
LOOK_EVERY_S = 1.0  # statvfs costs microseconds, but a put may come every millisecond
MEASURE_FOOTPRINT_AFTER = 32  # events, before which the footprint is only estimated

Row = TypeVar("Row")


@dataclass
class RoomEstimate:
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

    def forget(self) -> None:
        """Measure at the next put (the file changed under us: VACUUM, a drop)."""
        self.puts = RECHECK_EVERY


def wal_reserve(max_bytes: int) -> int:
    """The share of the byte cap kept for the WAL (SQLite's journal_size_limit), and
    the size of the full-disk reserve (``reserve.py``): each takes this much."""
    return wal_share(max_bytes)


class VolumeSpace:
    """The queue's volume as the put path sees it: ``statvfs`` and the sizes of the
    queue's files, looked at again at most once every LOOK_EVERY_S. The queue's own
    writes move bytes from "free" to "the queue's files", so the effective cap they
    give (``cap``) does not go stale between looks; only other writers move it."""

    def __init__(
        self, path: Path, max_bytes: int, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.path, self.max_bytes = path, max_bytes
        self._clock = clock
        # (when, the volume, the queue's files' bytes): one tuple, for other threads
        self._seen: tuple[float, Volume | None, int] = (-math.inf, None, 0)

    def _look(self) -> tuple[float, Volume | None, int]:
        now = self._clock()
        seen = self._seen
        if now - seen[0] >= LOOK_EVERY_S:
            volume = look_at(self.path.parent)
            seen = (now, volume, file_bytes(self.path) if volume is not None else 0)
            self._seen = seen
        return seen

    def look(self) -> Volume | None:
        """The volume now (within LOOK_EVERY_S); None when its folder is gone."""
        return self._look()[1]

    def cap(self) -> Cap:
        """The effective cap (``volume.effective_cap``)."""
        _, volume, files = self._look()
        return effective_cap(self.max_bytes, files, volume)

    def forget(self) -> None:
        """Look again at the next use."""
        self._seen = (-math.inf, None, 0)


class Caps:
    """Applies QueueLimits, and the volume (``volume``) when it holds less, to puts,
    inside the put's transaction."""

    def __init__(
        self,
        limits: QueueLimits,
        page_size: int,
        codecs: Codecs,
        frame_events: int,
        volume: VolumeSpace | None = None,
    ) -> None:
        self.limits = limits
        self.codecs, self.frame_events = codecs, frame_events
        self.volume = volume
        self.page_size = page_size
        self.room = RoomEstimate(self.cap().bytes, limits.max_events)

    def cap(self) -> Cap:
        """The effective cap now: QUEUE_MAX_BYTES, or what the volume can give."""
        if self.volume is None:
            return effective_cap(self.limits.max_bytes, 0, None)
        return self.volume.cap()

    @property
    def data_cap(self) -> int:
        """Bytes of database pages the events may use (``volume.Cap.bytes``)."""
        return self.cap().bytes

    def make_room(
        self, cursor: sqlite3.Cursor, rows: list[Row], sizes: list[int], now: float
    ) -> list[Row]:
        """Apply the caps before inserting ``rows`` (``sizes``: their stored bytes);
        returns the rows that may go in, oldest first."""
        incoming = sum(sizes)
        cap = self.cap()
        self.room.data_cap = cap.bytes
        if self.room.is_certain(len(rows), incoming):
            self.room.added(len(rows), incoming)
            return rows
        kept = self._make_room_measured(cursor, rows, sizes, now, cap)
        depth, used = depth_and_used_bytes(cursor, self.page_size)
        self.room.measured(depth + len(kept), used + sum(sizes[: len(kept)]))
        return kept

    def _make_room_measured(
        self, cursor: sqlite3.Cursor, rows: list[Row], sizes: list[int], now: float, cap: Cap
    ) -> list[Row]:
        limits = self.limits
        depth, used = depth_and_used_bytes(cursor, self.page_size)
        per_event = self._bytes_per_event(sizes, depth, used)
        under_event_cap = limits.max_events is None or depth + len(rows) <= limits.max_events
        if under_event_cap and used + per_event * len(rows) <= cap.bytes:
            return rows  # the common case: one query, no drops

        if limits.max_events is not None and depth + len(rows) > limits.max_events:
            excess = depth + len(rows) - limits.max_events
            if limits.makes_room:
                excess -= self._free(cursor, excess, "cap_events", now)
            if excess > 0:
                bump_counters(cursor, **{"drop:cap_events": min(excess, len(rows))})
                rows = rows[: max(0, len(rows) - excess)]

        def over() -> int:
            used = depth_and_used_bytes(cursor, self.page_size)[1]
            return used + per_event * len(rows) - cap.bytes

        # what is dropped for bytes: QUEUE_MAX_BYTES's, or a full volume's (thinning
        # counts as thinned either way)
        reason = "disk_full" if cap.limited_by == LIMIT_VOLUME else "cap_bytes"
        excess_bytes = over()
        # Deleted rows free whole pages only, so a round may free less than it deleted:
        # go on until the new rows fit or nothing unleased is left (each round deletes
        # at least one row, so this ends); new rows are refused only then.
        while (
            limits.makes_room
            and excess_bytes > 0
            and self._free(cursor, math.ceil(excess_bytes / per_event) + 1, reason, now)
        ):
            excess_bytes = over()
        if excess_bytes > 0:  # drop_newest, or everything older is being sent
            keep = max(0, len(rows) - math.ceil(excess_bytes / per_event))
            bump_counters(cursor, **{f"drop:{reason}": len(rows) - keep})
            rows = rows[:keep]
        return rows

    def _free(self, cursor: sqlite3.Cursor, count: int, reason: str, now: float) -> int:
        """Make room for about ``count`` events: thin, or drop the oldest."""
        if self.limits.on_full is not OnFull.THIN:
            return drop_oldest(cursor, count, reason, now)
        thinned = thin_oldest(cursor, self.codecs, count, now, max(2, self.frame_events))
        return thinned or drop_oldest(cursor, count, reason, now, periodic_first=True)

    def fitting(self, cursor: sqlite3.Cursor, sizes: list[int]) -> int:
        """How many of these rows (oldest first) fit under the caps without dropping
        anything: what a dead-letter requeue may move back."""
        if not sizes:
            return 0
        depth, used = depth_and_used_bytes(cursor, self.page_size)
        per_event = self._bytes_per_event(sizes, depth, used)
        fits = min(len(sizes), max(0, (self.cap().bytes - used) // per_event))
        if self.limits.max_events is not None:
            fits = min(fits, max(0, self.limits.max_events - depth))
        self.room.forget()
        return fits

    @staticmethod
    def _bytes_per_event(sizes: list[int], depth: int, used: int) -> int:
        """Disk bytes one incoming event will take: measured on the queue once it holds
        enough events, else estimated from the incoming sizes."""
        estimate = (sum(sizes) / len(sizes) + ROW_OVERHEAD_BYTES) * PAGE_FILL
        if depth >= MEASURE_FOOTPRINT_AFTER:
            estimate = max(estimate, used / depth)
        return math.ceil(estimate)


def drop_oldest(
    cursor: sqlite3.Cursor, count: int, reason: str, now: float, periodic_first: bool = False
) -> int:
    """Delete at least ``count`` oldest events not under a lease (whole rows: a frame
    goes at once), as many as there are; counted as ``reason``. ``periodic_first``:
    important events go only when no periodic ones are left to drop."""
    dropped = _drop_oldest_periodic(cursor, count, now) if periodic_first else 0
    if dropped:
        bump_counters(cursor, **{f"drop:{reason}": dropped})
        return dropped
    for chunk in leases.unleased(cursor, now, "id, last_id, count", count):
        if dropped >= count:
            break
        last, covered = None, 0
        for _, last_id, events in chunk.rows:
            if dropped + covered >= count:
                break
            last, covered = last_id, covered + events
        if last is not None:  # one delete for the chunk's oldest rows
            dropped += delete_range(cursor, chunk.low, last)
    bump_counters(cursor, **{f"drop:{reason}": dropped})
    return dropped


def _drop_oldest_periodic(cursor: sqlite3.Cursor, count: int, now: float) -> int:
    """Delete at least ``count`` of the oldest periodic events not under a lease."""
    dropped = 0
    periodic = leases.unleased(cursor, now, "id, last_id", count, where="AND important = 0")
    for chunk in periodic:
        for row_id, last_id in chunk.rows:
            if dropped >= count:
                return dropped
            dropped += delete_range(cursor, row_id, last_id)
    return dropped
