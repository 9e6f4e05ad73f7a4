"""Queue time: the clock every age, lease and schedule of the queue is read on.

A robot without a battery-backed clock boots in 2001 or at its last shutdown, and NTP
steps the wall clock minutes later, while events are queued. Ages read on the wall
clock would then jump by years (expiring a fresh backlog) or run backwards (keeping
leases forever). Queue time never steps:

- Within a boot it is ``CLOCK_BOOTTIME`` (which counts suspend and is shared by every
  process on the machine) plus a base that the first process of the boot stores in
  the ``clock`` table; every later process of the boot reads the same base.
- Across a reboot it continues from the last moment the previous boot recorded
  (``meta``'s ``clock_last_*``, written at open and at each maintenance pass) plus this
  boot's uptime, plus the time the machine was off *only when* the wall clock was
  synchronized both then and now (the kernel's ``adjtimex``): otherwise that time
  counts as zero, so an event is never treated as older than it could be.
- A new queue starts queue time at the wall clock, so on a good clock the two agree
  and the columns still read as unix seconds.

A step of the wall clock is seen as a change of ``wall - CLOCK_BOOTTIME`` larger than
``STEP_THRESHOLD_S`` (NTP slews smaller errors) and recorded in ``clock_steps``
(docs/queue.md, "Time").
"""

from __future__ import annotations

import functools
import sqlite3
import time
from collections.abc import Callable
from typing import NamedTuple

STEP_THRESHOLD_S = 1.0
BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"


class Instant(NamedTuple):
    """What the machine's clocks said at one moment."""

    wall: float  # unix seconds, as the wall clock says (may be wrong, may step)
    since_boot: float  # CLOCK_BOOTTIME seconds: never steps
    boot_id: str
    synchronized: bool  # the kernel says the wall clock is disciplined (adjtimex)


class LastSeen(NamedTuple):
    """The last moment a queue recorded: queue time, the wall clock then, and whether
    that wall clock was synchronized."""

    queue_time: float
    wall: float
    synchronized: bool


class SystemClocks:
    """The machine's clocks; tests pass an object with the same ``read``."""

    def read(self) -> Instant:
        return Instant(
            time.time(), time.clock_gettime(time.CLOCK_BOOTTIME), boot_id(), synchronized()
        )


@functools.cache
def boot_id() -> str:
    """The kernel's id of this boot (a container sees its host's); a fixed stand-in
    where there is none, so such a machine counts every start as the same boot."""
    try:
        with open(BOOT_ID_PATH, encoding="ascii") as file:
            return file.read().strip()
    except OSError:
        return "unknown"


def synchronized() -> bool:
    """Whether the kernel says the wall clock is synchronized (``adjtimex`` without
    STA_UNSYNC), read the way ``ntp_gettime`` does; False where it cannot tell."""
    import ctypes  # here: only the service and drain ask, never `status` at start-up

    class Timex(ctypes.Structure):  # struct timex up to `status`, then room for the rest
        _fields_ = [
            ("modes", ctypes.c_uint),
            ("offset", ctypes.c_long),
            ("freq", ctypes.c_long),
            ("maxerror", ctypes.c_long),
            ("esterror", ctypes.c_long),
            ("status", ctypes.c_int),
            ("rest", ctypes.c_byte * 256),
        ]

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        timex = Timex()
        state = libc.adjtimex(ctypes.byref(timex))
    except (OSError, AttributeError):
        return False
    sta_unsync, time_error = 0x0040, 5
    return state not in (-1, time_error) and not timex.status & sta_unsync


def boot_base(now: Instant, last: LastSeen | None) -> float:
    """The base of queue time for a boot that opens the queue first at ``now``: queue
    time = CLOCK_BOOTTIME + base. Pure."""
    if last is None:
        return now.wall - now.since_boot  # a new queue: queue time starts at the wall clock
    # at least this boot's uptime has passed since the last record; when both wall
    # clocks were true, what they say passed (the time off included)
    passed = now.since_boot
    if last.synchronized and now.synchronized:
        passed = max(passed, now.wall - last.wall)
    return last.queue_time + passed - now.since_boot


class QueueTime:
    """Queue time for one process: ``now()`` is CLOCK_BOOTTIME plus this boot's base."""

    def __init__(self, base: float, boot_id: str, clocks: SystemClocks) -> None:
        self.base = base
        self.boot_id = boot_id
        self.clocks = clocks
        self._offset: float | None = None  # wall - CLOCK_BOOTTIME at the last look

    def now(self) -> float:
        return self.clocks.read().since_boot + self.base

    def at(self, instant: Instant) -> float:
        return instant.since_boot + self.base

    def record(self, cursor: sqlite3.Cursor) -> float:
        """``record_moment`` now; the step of the wall clock seen (0.0 for none)."""
        return record_moment(cursor, self, self.clocks.read())

    def step_seen(self, instant: Instant) -> float:
        """How far the wall clock stepped since the last look (0.0 when it did not)."""
        offset = instant.wall - instant.since_boot
        previous, self._offset = self._offset, offset
        if previous is None or abs(offset - previous) <= STEP_THRESHOLD_S:
            return 0.0
        return offset - previous


def open_queue_time(
    write: Callable[[Callable[[sqlite3.Cursor], QueueTime]], QueueTime], clocks: SystemClocks
) -> QueueTime:
    """This boot's queue time, its base stored by the first process of the boot, in one
    write transaction (``Database.write``), so two processes opening at once agree."""
    return write(lambda cursor: _open(cursor, clocks))


def _open(cursor: sqlite3.Cursor, clocks: SystemClocks) -> QueueTime:
    now = clocks.read()
    row = cursor.execute("SELECT base FROM clock WHERE boot_id = ?", (now.boot_id,)).fetchone()
    if row is None:
        base = boot_base(now, last_seen(cursor))
        cursor.execute("INSERT INTO clock(boot_id, base) VALUES (?, ?)", (now.boot_id, base))
    else:
        base = float(row[0])
    queue_time = QueueTime(base, now.boot_id, clocks)
    record_moment(cursor, queue_time, now)
    return queue_time


def record_moment(cursor: sqlite3.Cursor, queue_time: QueueTime, now: Instant) -> float:
    """Write the last moment seen (for the next boot) and any step of the wall clock
    since the last look; the step in seconds (0.0 for none)."""
    step = queue_time.step_seen(now)
    at = queue_time.at(now)
    if step:
        cursor.execute(
            "INSERT OR REPLACE INTO clock_steps(at, step_s, boot_id) VALUES (?, ?, ?)",
            (at, step, now.boot_id),
        )
    cursor.executemany(
        "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
        [
            ("clock_last_queue_time", repr(at)),
            ("clock_last_wall", repr(now.wall)),
            ("clock_last_synchronized", "1" if now.synchronized else "0"),
        ],
    )
    return step


def last_seen(cursor: sqlite3.Cursor) -> LastSeen | None:
    """The last moment the queue recorded; for a queue from before queue time, the
    newest time in it, its wall clock unknown (so no time off is counted)."""
    meta = dict(cursor.execute("SELECT key, value FROM meta WHERE key LIKE 'clock_last_%'"))
    if "clock_last_queue_time" in meta:
        return LastSeen(
            float(meta["clock_last_queue_time"]),
            float(meta["clock_last_wall"]),
            meta.get("clock_last_synchronized") == "1",
        )
    newest = cursor.execute(
        "SELECT max(t) FROM (SELECT max(coalesce(newest_at, queued_at)) AS t FROM events "
        "UNION ALL SELECT max(heartbeat_at) FROM service_state)"
    ).fetchone()[0]
    return None if newest is None else LastSeen(float(newest), float(newest), False)


def queue_time_now(connection: sqlite3.Connection) -> float:
    """Queue time now, read without writing (``status``): this boot's base when a
    process stored one, else what the next open would choose with no time off."""
    now = Instant(
        time.time(), time.clock_gettime(time.CLOCK_BOOTTIME), boot_id(), synchronized=False
    )
    cursor = connection.cursor()
    tables = {name for (name,) in cursor.execute("SELECT name FROM sqlite_master")}
    if "clock" not in tables:  # a queue from before queue time: it was the wall clock
        return now.wall
    row = cursor.execute("SELECT base FROM clock WHERE boot_id = ?", (now.boot_id,)).fetchone()
    base = float(row[0]) if row else boot_base(now, last_seen(cursor))
    return now.since_boot + base
