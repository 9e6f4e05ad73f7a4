"""Events into the queue: encoded one by one, let in by the caps, inserted and counted
in one transaction (group commit); then what has waited is sealed into frames.

The store's write side (``QueueStore.put_many``). Every event put is counted in
``queued_total`` whatever became of it: kept, dropped by a cap, refused by a full disk,
or dropped alone because JSON cannot hold it (``unencodable``). Events that never reach
``put`` (the writer's hand-off was full, the disk failed until a stop) are counted here
too (``count_unqueued``), so that built = delivered + queued + dead-lettered + dropped.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Sequence

import orjson

from phytrace_edge.errors import QueueError, QueueFullError
from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S, Sealer
from phytrace_edge.queue.records import INCIDENT_CLASS, PutResult
from phytrace_edge.queue.space.caps import Caps, wal_reserve
from phytrace_edge.queue.space.full_disk import FullDisk
from phytrace_edge.queue.storage.database import Database, bump_counters
from phytrace_edge.queue.storage.rows import NewRow, insert_rows
from phytrace_edge.queue.timekeeping.repair import ClockKeeper
from phytrace_edge.udm.types import Built, UdmEvent

log = logging.getLogger(__name__)


def row_class(event: UdmEvent, important: bool) -> int:
    """The class a row is stored with: 0 periodic, 1 important, ``INCIDENT_CLASS`` an
    incident's part (important, and sent before the rest of a backlog)."""
    if event.get("event_type") == "incident":
        return INCIDENT_CLASS
    return int(important)


class Appender:
    """Puts events into one queue database."""

    def __init__(
        self,
        db: Database,
        codecs: Codecs,
        caps: Caps,
        full_disk: FullDisk,
        sealer: Sealer,
        clock: Callable[[], float],
        clocks: ClockKeeper | None,
    ) -> None:
        self._db = db
        self._codecs = codecs
        self._caps = caps
        self._full_disk = full_disk
        self._sealer = sealer
        self._clock = clock
        self._clocks = clocks
        self._seal_after = 0.0  # store clock: no sealing before (the disk was full)

    def put_many(
        self,
        built: Sequence[Built],
        after_commit: Callable[[], None] | None,
        upkeep: bool,
    ) -> PutResult:
        """Queue events in one transaction (group commit), each with its class. Never
        raises for a full queue or a full disk: what cannot be kept is counted as a
        drop and logged. ``after_commit`` runs once they are counted, under the queue's
        lock (``locked``). Without ``upkeep`` (a stop), what has waited is not sealed
        into frames now."""
        now = self._clock()  # when these were queued (queue time)
        encoded = [self._encode(event, important, now) for event, important in built]
        rows = [row for row in encoded if row is not None]
        unencodable = len(encoded) - len(rows)  # counted with the rows, once they commit
        if not encoded:
            return PutResult(0, 0)
        try:
            return self._insert(rows, unencodable, after_commit, upkeep, now)
        except QueueFullError:
            if self._caps.limits.makes_room and self._full_disk.make_room(
                [len(row.body) for row in rows],
                max(len(rows), self._db.counter("depth") // 100),
                self._clock(),
            ):
                with contextlib.suppress(QueueFullError):
                    return self._insert(rows, unencodable, after_commit, upkeep, self._clock())
            with self._db.lock:
                self._full_disk.refused(self._db.path, len(rows))
                if unencodable:
                    self.count_unqueued("unencodable", unencodable)
                if after_commit is not None:
                    after_commit()
            return PutResult(0, len(encoded))

    def _encode(self, event: UdmEvent, important: bool, now: float) -> NewRow | None:
        """The row of one event, queued at ``now``; None (logged) for an event JSON
        cannot hold, so that one bad event never costs its group."""
        try:
            raw = orjson.dumps(event)
        except orjson.JSONEncodeError as exc:
            log.error(
                "event %s of type %s cannot be written as JSON (%s); dropped (unencodable)",
                event.get("event_id"),
                event.get("event_type"),
                exc,
            )
            return None
        at_rest = self._codecs.encode(raw)
        return NewRow(
            event_id=str(event.get("event_id", "")),
            important=row_class(event, important),
            queued_at=now,
            codec=at_rest.codec,
            dict_id=at_rest.dict_id,
            json_size=len(raw),
            body=at_rest.body,
        )

    def count_unqueued(self, reason: str, count: int) -> None:
        """Count ``count`` events that were built but never reached the queue (the
        writer's hand-off was full, the disk failed until a stop, an event could not be
        encoded): as put and dropped by ``reason``, so that the queue's counters still
        add up. Written with the next transaction that commits (the disk may be
        failing now)."""
        self._db.defer_counts(**{f"drop:{reason}": count, "queued_total": count})

    def _insert(
        self,
        rows: list[NewRow],
        unencodable: int,
        after_commit: Callable[[], None] | None,
        upkeep: bool,
        now: float,
    ) -> PutResult:
        sizes = [len(row.body) for row in rows]
        if rows and self._full_disk.refuses(sizes):
            raise QueueFullError(f"queue {self._db.path}: disk full")
        with self._db.transaction(after_commit=after_commit) as cursor:
            accepted = self._caps.make_room(cursor, rows, sizes, now) if rows else []
            insert_rows(
                cursor,
                accepted,
                queued_total=len(rows),  # every event put, whatever the caps did with it
            )
            if self._clocks:  # stamped before a step already recorded (queue/timekeeping/repair.py)
                self._clocks.repair_put(cursor, len(accepted))
            bump_counters(cursor, **{"drop:unencodable": unencodable, "queued_total": unencodable})
        if upkeep:
            self._seal(now)
            self._db.bound_wal(wal_reserve(self._caps.cap().files))  # the volume's share
        return PutResult(len(accepted), len(rows) + unencodable - len(accepted))

    def _seal(self, now: float) -> None:
        """Pack what has waited into frames, in a transaction of its own after the put:
        the put is durable whatever happens here."""
        if now < self._seal_after:
            return
        if not self._full_disk.has_room_to_seal():
            self._seal_after = now + SEAL_AFTER_S
            return
        looked_below = self._sealer.sealed_below
        try:
            with self._db.transaction() as cursor:
                sealed = self._sealer.seal(cursor, now)
        except QueueError:
            self._sealer.sealed_below = looked_below  # rolled back: look again later
            self._seal_after = now + SEAL_AFTER_S
            return
        if sealed:
            self._caps.room.forget()
