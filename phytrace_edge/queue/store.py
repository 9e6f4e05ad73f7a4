"""QueueStore: the durable hand-off between build and ship, one SQLite file in WAL mode.

Build appends (``put_many``, each event with its class); ship claims the oldest
(``claim_batch``) or newest (``claim_live``) under a lease, and deletes them only once
PhyCloud accepted them (``ack``) or gives them back (``release``). ``put`` returns
after its commit (QUEUE_SYNC=full: an fsync; docs/queue.md, "What survives what").
Events that wait are packed into frames (``frames``); every time stored is queue time
(``clock``), which never steps with the wall clock.

Every event that leaves other than by ``ack`` is counted by reason: ``thinned``,
``cap_bytes``, ``cap_events``, ``ttl``, ``disk_full``, ``rejected`` (dead-lettered).
Thread-safe: each use of the connection holds its lock; each thread has its compressors.
"""

from __future__ import annotations

import functools
import itertools
import logging
import sqlite3
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phytrace_edge.errors import QueueDamagedError, QueueError
from phytrace_edge.queue.appender import Appender
from phytrace_edge.queue.defaults import (
    DEFAULT_BUSY_TIMEOUT_S,
    DEFAULT_COMPRESSION,
    DEFAULT_LEASE_S,
    DEFAULT_SYNC,
)
from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.encoding.dictionaries import load_dictionaries
from phytrace_edge.queue.encoding.frames import FRAME_EVENTS, Sealer, decode_rows
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.outbound import claims, leases
from phytrace_edge.queue.outbound.dead_letters import DeadLetterBox, dead_letter_row
from phytrace_edge.queue.outbound.ownership import Owner, dead_owners, sweep_dead_owners
from phytrace_edge.queue.peek import QueueStats, file_bytes, stats_from
from phytrace_edge.queue.records import Batch, DeadLetter, PutResult
from phytrace_edge.queue.space import maintenance
from phytrace_edge.queue.space.caps import Caps, VolumeSpace, wal_reserve
from phytrace_edge.queue.space.full_disk import FullDisk
from phytrace_edge.queue.space.reserve import SpaceReserve, warn_if_volume_smaller_than
from phytrace_edge.queue.storage import file_watch
from phytrace_edge.queue.storage.database import Database, configure
from phytrace_edge.queue.storage.migrate import migrate
from phytrace_edge.queue.storage.recovery import check_integrity, mark_damaged, open_checked
from phytrace_edge.queue.storage.service_state import write_service_state
from phytrace_edge.queue.storage.sqlite_errors import queue_error
from phytrace_edge.queue.timekeeping.clock import SystemClocks
from phytrace_edge.queue.timekeeping.repair import ClockKeeper
from phytrace_edge.udm.types import Built, UdmEvent

log = logging.getLogger(__name__)

INTEGRITY_EVERY_S = 24 * 3600.0


@dataclass(frozen=True)
class StoreSetup:
    """How a store is set up, as ``QueueStore.open`` was asked (see there)."""

    limits: QueueLimits
    compression: str
    clock: Callable[[], float] | None
    clocks: SystemClocks | None
    lease_s: float
    frame_events: int


class QueueStore:
    """The queue database; open it with ``QueueStore.open``."""

    def __init__(self, db: Database, setup: StoreSetup) -> None:
        limits, clock, frame_events = setup.limits, setup.clock, setup.frame_events
        self._db = db
        self.path = db.path
        self.limits = limits
        self.lease_s = setup.lease_s
        self._owner = Owner(db.path)
        self.codecs = Codecs(setup.compression)
        # queue time (queue/timekeeping/clock.py) and repairs after a step, unless a
        # test brings a clock
        self._clocks = (
            None
            if clock
            else ClockKeeper(
                db, setup.clocks or SystemClocks(), self.codecs, self._owner.token, setup.lease_s
            )
        )
        self._clock = clock or self._clocks.queue_time.now  # type: ignore[union-attr]
        self._claims = itertools.count(1)
        self.busy_timeout_s = DEFAULT_BUSY_TIMEOUT_S
        self.next_check_at = time.monotonic() + INTEGRITY_EVERY_S  # monotonic
        volume = VolumeSpace(db.path, limits.max_bytes)  # the cap follows the volume
        self._caps = Caps(limits, db.page_size, self.codecs, frame_events, volume)
        self._wal_reserve = wal_reserve(limits.max_bytes)
        self._full_disk = FullDisk(db, volume)
        db.size_wal(self._wal_reserve)
        load_dictionaries(db, self.codecs, self._clock())
        self._sealer = Sealer(self.codecs, frame_events)
        self._appender = Appender(
            db, self.codecs, self._caps, self._full_disk, self._sealer, self._clock, self._clocks
        )
        self.dead_letters = DeadLetterBox(db, self.codecs, self._caps, self._clock)
        self.file_keeper = file_watch.FileKeeper(db, self._wal_reserve)

    @classmethod
    def open(
        cls,
        path: str | Path,
        *,
        limits: QueueLimits | None = None,
        compression: str = DEFAULT_COMPRESSION,
        sync: str = DEFAULT_SYNC,
        clock: Callable[[], float] | None = None,
        clocks: SystemClocks | None = None,
        lease_s: float = DEFAULT_LEASE_S,
        busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S,
        frame_events: int = FRAME_EVENTS,
    ) -> QueueStore:
        """Open (creating, checking, migrating) the queue at ``path``.

        A corrupt or non-SQLite file is moved aside and a fresh queue started (see
        ``recovery``); the store remembers the moved file for ``stats``. Its clock is
        queue time (``queue/timekeeping/clock.py``) read from ``clocks``; tests of ages pass a
        ``clock`` of their own instead, and a small ``frame_events`` to see frames form.
        """
        setup = StoreSetup(
            limits=limits or QueueLimits(),
            compression=compression,
            clock=clock,
            clocks=clocks,
            lease_s=lease_s,
            frame_events=frame_events,
        )
        try:
            return cls._open_once(Path(path), sync, busy_timeout_s, setup)
        except QueueDamagedError:
            # damage the bounded check at open did not reach: now marked, so this
            # open checks the file whole and moves it aside
            return cls._open_once(Path(path), sync, busy_timeout_s, setup)

    @classmethod
    def _open_once(
        cls, path: Path, sync: str, busy_timeout_s: float, setup: StoreSetup
    ) -> QueueStore:
        connection, quarantined, checked_whole = open_checked(path, busy_timeout_s)
        try:
            configure(connection, sync)
            migrate(connection)
        except sqlite3.Error as exc:
            connection.close()
            error = queue_error(exc, path)
            if isinstance(error, QueueDamagedError):
                mark_damaged(path, str(exc))
            raise error from exc
        reserve = SpaceReserve.sized_for(path, wal_reserve(setup.limits.max_bytes))
        try:
            store = cls(Database(connection, path, reserve), setup)
        except QueueError:
            connection.close()
            raise
        if quarantined is not None:
            sql = "INSERT OR REPLACE INTO meta(key, value) VALUES ('quarantined', ?)"
            store._db.write(lambda cursor: cursor.execute(sql, (str(quarantined),)))
        store.busy_timeout_s = busy_timeout_s
        store.next_check_at = time.monotonic() + (INTEGRITY_EVERY_S if checked_whole else 0.0)
        store.take_back_orphaned_leases()
        sweep_dead_owners(path)
        reserve.restore()
        warn_if_volume_smaller_than(path, store.file_bytes(), setup.limits.max_bytes)
        return store

    def close(self) -> None:
        self._db.close()
        self._owner.close()
        self.file_keeper.close()

    def watch_file(self) -> file_watch.FileState:
        """Whether the queue file is still at its path; a file deleted, moved or
        replaced is copied back from the open connection (``file_watch``). Called every
        heartbeat."""
        return self.file_keeper.watch()

    def now(self) -> float:
        """Queue time (``clock``), which never steps, or a test's own clock."""
        return self._clock()

    def __enter__(self) -> QueueStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ put

    def put(self, event: UdmEvent, important: bool = False) -> PutResult:
        """Queue one event; returns once it is durable (see module doc)."""
        return self.put_many([Built(event, important)])

    def put_many(
        self,
        built: Sequence[Built],
        after_commit: Callable[[], None] | None = None,
        upkeep: bool = True,
    ) -> PutResult:
        """Queue events, each with its class, in one transaction (group commit):
        ``Appender.put_many``."""
        return self._appender.put_many(built, after_commit, upkeep)

    def count_unqueued(self, reason: str, count: int) -> None:
        """Count events built that never reached the queue: ``Appender.count_unqueued``."""
        self._appender.count_unqueued(reason, count)

    def defer_counts(self, counts: Mapping[str, int]) -> None:
        """Add counts with the next transaction that commits (a previous run's)."""
        self._db.defer_counts(**counts)

    def unwritten_counts(self) -> dict[str, int]:
        """Counts kept in memory because the queue could not be written."""
        return self._db.deferred_counts()

    # ------------------------------------------------------------------ claim / ack

    def claim_batch(
        self, max_events: int, max_bytes: int, important_first: bool = True
    ) -> Batch | None:
        """The backfill lane: lease the oldest unleased events, at most ``max_events``
        and ``max_bytes`` of JSON (but always one, however large); with
        ``important_first`` the important events of the oldest hour go first
        (``claims.lease_oldest``). None when there is nothing to send."""
        if self._db.counter("depth") == 0:
            return None
        lease = functools.partial(claims.lease_oldest, important_first=important_first)
        batch = self._claim(lease, (max_events, max_bytes))
        if batch is None and self.take_back_orphaned_leases():
            # everything left was claimed, and some of it by a process that died
            batch = self._claim(lease, (max_events, max_bytes))
        return batch

    def claim_live(self, max_events: int, max_bytes: int, since: float) -> Batch | None:
        """The live lane: lease the newest unleased events queued at or after
        ``since`` (store clock), newest batch first. None when there are none."""
        if self._db.counter("depth") == 0:
            return None
        lease = functools.partial(claims.lease_newest, since=since)
        return self._claim(lease, (max_events, max_bytes))

    def _claim(self, lease: Callable[..., Any], limits: tuple[int, int]) -> Batch | None:
        if self._clocks and self._clocks.due():
            self._clocks.look()  # repair before sending
        now = self._clock()
        # each claim its own token: releasing a stale claim never frees a newer one
        token = f"{self._owner.token}:{next(self._claims)}"
        ranges, rows = self._db.write(
            lambda cursor: lease(cursor, limits, token, now, now + self.lease_s), durable=False
        )
        if not rows:
            return None
        events = decode_rows(self.codecs, rows)  # outside the lock: others go on
        return Batch(tuple(ranges), token, events, now)

    def ack(
        self, batch: Batch, dead_letters: Sequence[DeadLetter] = (), exported: bool = False
    ) -> None:
        """PhyCloud has the batch (or, ``exported``, a verified hand-carry file has it):
        delete it, moving ``dead_letters`` aside first."""
        now, counter = self._clock(), "exported_total" if exported else "acked_total"
        by_id = {event.id: event for event in batch.events} if dead_letters else {}
        rows = [dead_letter_row(self.codecs, by_id[d.queue_id], d) for d in dead_letters]
        self._db.write(
            lambda cursor: claims.delete_accepted(cursor, batch, rows, now, self.codecs, counter),
            durable=exported,  # an export deletes what only a file on a stick now holds
        )

    def take_back_orphaned_leases(self) -> int:
        """Free the events claimed by processes that died (killed, crashed, a container
        removed) without waiting for their leases to run out; the count of leases."""
        now = self._clock()
        owners = self._db.read("SELECT DISTINCT owner FROM leases WHERE expires_at > ?", (now,))
        dead = dead_owners(self.path, {owner for (owner,) in owners}, self._owner.token)
        if dead:  # a write only when there is something to take back
            self._db.write(lambda cursor: leases.take_back(cursor, dead))
            log.warning(
                "queue %s: took back the claims of %d process(es) that died while sending",
                self.path,
                len(dead),
            )
        return len(dead)

    def release(self, batch: Batch) -> None:
        """Give the batch back unsent: its events are claimable again at once."""
        self._db.write(lambda cursor: leases.give_back(cursor, batch.owner), durable=False)

    def renew(self, batch: Batch) -> bool:
        """Extend the lease while a send is still retrying; False if it had expired
        (another sender may have the events now: send them anyway, PhyCloud dedupes)."""
        now, until = self._clock(), self._clock() + self.lease_s
        return self._db.write(
            lambda cursor: leases.extend(cursor, batch.owner, now, until),
            durable=False,
        )

    # ------------------------------------------------------------------ upkeep

    def expire(self) -> int:
        """Delete events older than QUEUE_TTL_S (not those being sent); the count."""
        now = self._clock()
        expired = maintenance.expire(self._db, now - self.limits.ttl_s, now)
        if expired:
            log.warning("queue %s: %d event(s) older than QUEUE_TTL_S expired", self.path, expired)
        return expired

    def record_clocks(self) -> float:
        """Write the last moment seen (the next boot's queue time goes on from it); a
        step of the wall clock's seconds, 0.0 for none (``repair.ClockKeeper.look``)."""
        return self._clocks.look() if self._clocks else 0.0

    def stepped_since(self, at: float) -> bool:
        """Whether the wall clock stepped after ``at`` (a batch's stamps were repaired)."""
        return bool(self._db.read("SELECT 1 FROM clock_steps WHERE at > ? LIMIT 1", (at,)))

    def reclaim_space(self, force: bool = False) -> int:
        """Give free pages back to the file system (see ``maintenance``); bytes freed."""
        before = self.file_bytes()
        maintenance.reclaim_space(self._db, force)
        self._caps.room.forget()
        return max(0, before - self.file_bytes())

    def maintain(self) -> None:
        """Periodic upkeep: the clocks' last moment (and any step of the wall clock),
        TTL expiry, space reclaim, the integrity check the open did not finish (then
        daily), and the full-disk reserve again once the disk has room."""
        self.record_clocks()
        self.expire()
        self.reclaim_space()
        if time.monotonic() >= self.next_check_at:
            self.next_check_at = time.monotonic() + INTEGRITY_EVERY_S
            check_integrity(self.path, self.busy_timeout_s)
        self._full_disk.restore_reserve()

    # ------------------------------------------------------------------ state

    def write_service_state(
        self, document: Mapping[str, Any], running: bool, durable: bool = True
    ) -> None:
        """Record the running service's figures for ``status`` (another process)."""
        write_service_state(self._db, document, running, self._clock(), durable)

    def locked(self) -> threading.RLock:
        """The queue's lock: what is read under it is one moment of the queue (a put's
        ``after_commit`` runs under it too)."""
        return self._db.lock

    def counter(self, name: str) -> int:
        """One of the queue's exact counters (``depth``, ``stored_bytes``, ...)."""
        return self._db.counter(name)

    def backlog(self) -> tuple[int, float | None]:
        """(events queued, when the oldest was queued): two indexed lookups."""
        depth, oldest = self._db.read(
            "SELECT (SELECT value FROM counters WHERE name = 'depth'), "
            "(SELECT queued_at FROM events ORDER BY id LIMIT 1)"
        )[0]
        return int(depth or 0), oldest

    def file_bytes(self) -> int:
        """Bytes on disk: the database, its WAL and shared-memory files."""
        return file_bytes(self.path)

    def stats(self) -> QueueStats:
        """What ``status`` shows about the queue (drops not yet written included)."""
        now = self._clock()
        wall = self._clocks.queue_time.clocks.now_wall() if self._clocks else now  # dates
        with self._db.lock:
            try:
                stats = stats_from(self._db.connection, str(self.path), now, wall - now)
            except sqlite3.Error as exc:
                raise queue_error(exc, self.path) from exc
        return stats.with_deferred(self._db.deferred_counts(), self.limits.max_bytes)
