"""What the queue holds and what its service last said, read cheaply and without
writing: the ``QueueStats`` that ``status``, the metrics and the heartbeat show.

``read_stats(path)`` opens the file read-only from any process (``status`` while the
service runs, or after it stopped); ``QueueStore.stats()`` reads the same through the
store's own connection. Both go through ``stats_from``, so they cannot disagree.

On the start-up path of ``status`` (the container's health check runs it every 30 s):
it imports nothing outside the standard library.
"""

import json
import os
import sqlite3
import stat
import time
from typing import Any, NamedTuple

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.space.volume import Cap, Volume, effective_cap, look_at
from phytrace_edge.queue.storage.sqlite_errors import queue_error
from phytrace_edge.queue.timekeeping.clock import queue_time_now

READ_TIMEOUT_S = 5.0
DAMAGED_SUFFIX = ".damaged"  # written by ``recovery`` when a check finds damage


class ServiceState(NamedTuple):
    """The running service's last heartbeat (``service_state.py`` writes it)."""

    heartbeat_at: float
    running: bool
    document: dict[str, Any]


class ClockState(NamedTuple):
    """The machine's clock as the queue last saw it (``queue/timekeeping/clock.py``)."""

    wall_offset: float  # wall clock minus queue time when read: turns queue times into dates
    synchronized: bool | None  # at the last record; None for a queue from before queue time
    last_step_s: float | None  # the last step of the wall clock seen, + forward
    last_step_at: float | None  # when (queue time)


class QueueStats(NamedTuple):
    """The queue's counters and oldest/newest events, its files' size and its volume's
    room (``effective_cap``), and the service's last heartbeat (None when no service
    ever ran on this queue).

    A NamedTuple, as the other records on ``status``'s path: ``dataclasses`` imports
    ``inspect``, 7 ms of a health check's 30 (docs/benchmarks.md, "Start-up")."""

    path: str
    counters: dict[str, int]
    oldest_queued_at: float | None
    newest_queued_at: float | None
    file_bytes: int
    quarantined: str | None
    leased: int
    service: ServiceState | None = None
    max_bytes: int = 0
    damaged: str | None = None
    resolution: tuple[dict[str, Any], ...] = ()
    clock: ClockState = ClockState(0.0, None, None, None)
    read_at: float = 0.0  # queue time
    volume: Volume | None = None  # the queue's volume when read; None: its folder is gone

    def effective_cap(self, max_bytes: int | None = None) -> Cap:
        """The bytes the queue's events may take, and which limit set them:
        QUEUE_MAX_BYTES (``max_bytes``, by default the store's), or what the volume
        can give the queue when that is less (``volume.effective_cap``)."""
        cap = self.max_bytes if max_bytes is None else max_bytes
        return effective_cap(cap, self.file_bytes, self.volume)

    @property
    def held_bytes(self) -> int:
        """Bytes of the events the queue holds (the ``stored_bytes`` counter): what a
        drain frees, unlike the file's size, which shrinks only at a VACUUM."""
        return self.stored_bytes

    def with_deferred(self, deferred: dict[str, int], max_bytes: int) -> "QueueStats":
        """These stats as the store sees them: its cap, and the counts kept in memory
        and not yet written (the disk was full or failing) added to the counters."""
        counters = dict(self.counters)
        for name, count in deferred.items():
            counters[name] = counters.get(name, 0) + count
        return self._replace(max_bytes=max_bytes, counters=counters)

    @property
    def depth(self) -> int:
        return self.counters.get("depth", 0)

    @property
    def stored_bytes(self) -> int:
        return self.counters.get("stored_bytes", 0)

    @property
    def queued_total(self) -> int:
        return self.counters.get("queued_total", 0)

    @property
    def acked_total(self) -> int:
        return self.counters.get("acked_total", 0)

    @property
    def exported_total(self) -> int:
        """Events that left in verified hand-carry files (``export``)."""
        return self.counters.get("exported_total", 0)

    @property
    def dead_letters(self) -> int:
        return self.counters.get("dead_letters", 0)

    @property
    def drops(self) -> dict[str, int]:
        """Events that left the queue other than by delivery, by reason."""
        drops = {k[5:]: v for k, v in self.counters.items() if k.startswith("drop:") and v}
        return {reason: n for reason, n in drops.items() if n}


def file_bytes(path: str | os.PathLike[str]) -> int:
    """Bytes on disk of the queue: the database, its WAL and shared-memory files, and
    its full-disk reserve."""
    total = 0
    for suffix in ("", "-wal", "-shm", "-reserve"):
        try:
            total += os.stat(f"{os.fspath(path)}{suffix}").st_size
        except OSError:  # not there, or its folder is gone
            continue
    return total


def stats_from(
    connection: sqlite3.Connection, path: str, now: float, wall_offset: float = 0.0
) -> QueueStats:
    """Read the stats through ``connection`` (the caller holds any lock it needs) at
    ``now`` (queue time), ``wall_offset`` being the wall clock minus queue time."""
    tables = {name for (name,) in connection.execute("SELECT name FROM sqlite_master")}
    if not tables:  # made, then a power cut before its first commit: what run opens empty
        return QueueStats(
            path=str(path),
            counters={},
            oldest_queued_at=None,
            newest_queued_at=None,
            file_bytes=file_bytes(path),
            volume=look_at(os.path.dirname(os.path.abspath(path))),
            quarantined=None,
            leased=0,
            damaged=_damage_found(path),
            clock=ClockState(wall_offset, None, None, None),
            read_at=now,
        )
    if "counters" not in tables:
        raise QueueError(f"queue {path}: not a phytrace-edge queue - check QUEUE_PATH")
    counters = {
        name: int(value) for name, value in connection.execute("SELECT name, value FROM counters")
    }
    oldest = connection.execute("SELECT queued_at FROM events ORDER BY id LIMIT 1").fetchone()
    # status reads a queue as it is: one from before frames (0004) has no newest_at
    columns = {row[1] for row in connection.execute("PRAGMA table_info(events)")}
    newest_at = "coalesce(newest_at, queued_at)" if "newest_at" in columns else "queued_at"
    newest = connection.execute(
        f"SELECT {newest_at} FROM events ORDER BY id DESC LIMIT 1"  # noqa: S608
    ).fetchone()
    quarantined = connection.execute("SELECT value FROM meta WHERE key = 'quarantined'").fetchone()
    leased = connection.execute(
        "SELECT count(*) FROM leases WHERE expires_at > ?", (now,)
    ).fetchone()[0]
    row = None
    if "service_state" in tables:  # a queue from before the heartbeat existed has none
        row = connection.execute(
            "SELECT heartbeat_at, running, document FROM service_state WHERE id = 1"
        ).fetchone()
    service = ServiceState(row[0], bool(row[1]), json.loads(row[2])) if row else None
    return QueueStats(
        path=str(path),
        counters=counters,
        oldest_queued_at=oldest[0] if oldest else None,
        newest_queued_at=newest[0] if newest else None,
        file_bytes=file_bytes(path),
        volume=look_at(os.path.dirname(os.path.abspath(path))),
        quarantined=quarantined[0] if quarantined else None,
        leased=int(leased),
        service=service,
        damaged=_damage_found(path),
        clock=_clock_state(connection, tables, wall_offset),
        read_at=now,
        # only a thinned queue has bands to show; the others need no scan
        resolution=_resolution(connection, now) if counters.get("drop:thinned") else (),
    )


def _resolution(connection: sqlite3.Connection, now: float) -> tuple[dict[str, Any], ...]:
    """The periodic history's resolution by age, oldest first: for each thinning level
    present, the ages it spans and the events it holds (``thinning``). Reads every row's
    small columns, not the bodies: a frame of 100 events is one row."""
    bands = connection.execute(
        "SELECT thin_level, min(queued_at), max(coalesce(newest_at, queued_at)), sum(count) "
        "FROM events WHERE important = 0 GROUP BY thin_level ORDER BY thin_level DESC"
    ).fetchall()
    return tuple(
        {
            "keeps": f"1 in {2**level}" if level else "all",
            "oldest_age_s": round(max(0.0, now - oldest), 1),
            "newest_age_s": round(max(0.0, now - newest), 1),
            "events": int(events),
        }
        for level, oldest, newest, events in bands
    )


def _clock_state(
    connection: sqlite3.Connection, tables: set[str], wall_offset: float
) -> ClockState:
    if "clock_steps" not in tables:  # a queue from before queue time
        return ClockState(wall_offset, None, None, None)
    synchronized = connection.execute(
        "SELECT value FROM meta WHERE key = 'clock_last_synchronized'"
    ).fetchone()
    step = connection.execute("SELECT step_s, at FROM clock_steps ORDER BY at DESC LIMIT 1")
    last_step_s, last_step_at = step.fetchone() or (None, None)
    return ClockState(
        wall_offset,
        None if synchronized is None else synchronized[0] == "1",
        last_step_s,
        last_step_at,
    )


def _damage_found(path: str) -> str | None:
    """What the last integrity check found wrong, if it did (``recovery``)."""
    try:
        with open(f"{path}{DAMAGED_SUFFIX}", encoding="utf-8") as marker:
            return marker.read().strip() or "damaged"
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"cannot read the damage marker ({exc.strerror})"


def read_stats(path: str, now: float | None = None) -> QueueStats | None:
    """The stats of the queue at ``path`` without writing to it, at ``now`` (queue
    time; by default the queue's own now); None when there is no file there. Raises a
    one-line ``QueueError`` for anything that is not a readable queue (a directory, a
    device, another application's file, a corrupt file)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise QueueError(f"queue {path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise QueueError(f"queue {path}: not a regular file - set QUEUE_PATH to the queue file")
    folder = os.path.dirname(os.path.abspath(path))
    uri = "file:" + os.path.abspath(path).replace("%", "%25").replace("?", "%3f")
    uri = uri.replace("#", "%23")
    # A queue on a read-only volume (an SD card mounted ro to look at it) cannot get the
    # shared-memory file WAL readers need: it is read as it is on disk, without a WAL.
    # (statvfs tells a read-only mount; root may write anywhere else.)
    read_only = os.statvfs(folder).f_flag & os.ST_RDONLY or not os.access(folder, os.W_OK)
    options = "mode=ro&immutable=1" if read_only else "mode=ro"
    try:
        connection = sqlite3.connect(f"{uri}?{options}", uri=True, timeout=READ_TIMEOUT_S)
        try:
            now = queue_time_now(connection) if now is None else now
            return stats_from(connection, path, now, wall_offset=time.time() - now)
        finally:
            connection.close()
    except sqlite3.Error as exc:
        raise queue_error(exc, path) from None
