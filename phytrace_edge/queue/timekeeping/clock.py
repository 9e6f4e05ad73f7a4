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

import sqlite3
import time
from collections.abc import Callable
from typing import NamedTuple

from phytrace_edge.host_clock import boot_id, synchronized

STEP_THRESHOLD_S = 1.0


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


class Step(NamedTuple):
    """A step of the wall clock, in queue time: seen at ``at``; the look before it, at
    ``looked_at``, saw none. Offsets are the wall clock minus queue time."""

    at: float
    looked_at: float
    offset_before: float
    offset_after: float

    @property
    def seconds(self) -> float:
        return self.offset_after - self.offset_before


class SystemClocks:
    """The machine's clocks; tests pass an object with the same methods."""

    def now_since_boot(self) -> float:
        return time.clock_gettime(time.CLOCK_BOOTTIME)

    def now_wall(self) -> float:
        return time.time()

    def read(self, ask_kernel: bool = True) -> Instant:
        """All of it, the kernel's word on synchronization included (a system call);
        without ``ask_kernel``, taken as not synchronized (no time off counted)."""
        return Instant(
            self.now_wall(),
            self.now_since_boot(),
            boot_id(),
            ask_kernel and synchronized() is True,  # "will not say" counts no time off
        )


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

    def __init__(self, base: float, clocks: SystemClocks) -> None:
        self.base = base
        self.clocks = clocks
        self._last_look: tuple[float, float] | None = None  # (queue time, wall offset)

    def now(self) -> float:
        return self.clocks.now_since_boot() + self.base

    def stepped(self) -> bool:
        """Whether the wall clock stepped since the last look (``record``), without
        looking: cheap enough for every claim."""
        if self._last_look is None:
            return False
        offset = self.clocks.now_wall() - self.now()
        return abs(offset - self._last_look[1]) > STEP_THRESHOLD_S

    def at(self, instant: Instant) -> float:
        return instant.since_boot + self.base

    def record(self, cursor: sqlite3.Cursor) -> Step | None:
        """``record_moment`` now; the step of the wall clock seen, if one was."""
        return record_moment(cursor, self, self.clocks.read())

    def step_seen(self, instant: Instant) -> Step | None:
        """The step of the wall clock since the last look, if there was one."""
        at = self.at(instant)
        offset = instant.wall - at
        previous, self._last_look = self._last_look, (at, offset)
        if previous is None or abs(offset - previous[1]) <= STEP_THRESHOLD_S:
            return None
        return Step(at, previous[0], previous[1], offset)


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
    queue_time = QueueTime(base, clocks)
    record_moment(cursor, queue_time, now)
    return queue_time


def record_moment(cursor: sqlite3.Cursor, queue_time: QueueTime, now: Instant) -> Step | None:
    """Write the last moment seen (for the next boot) and any step of the wall clock
    since the last look, which it returns."""
    step = queue_time.step_seen(now)
    at = queue_time.at(now)
    if step:
        cursor.execute(
            "INSERT OR REPLACE INTO clock_steps(at, step_s, boot_id) VALUES (?, ?, ?)",
            (at, step.seconds, now.boot_id),
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
    now = SystemClocks().read(ask_kernel=False)  # no ctypes at status's start
    cursor = connection.cursor()
    tables = {name for (name,) in cursor.execute("SELECT name FROM sqlite_master")}
    if "clock" not in tables:  # a queue from before queue time: it was the wall clock
        return now.wall
    row = cursor.execute("SELECT base FROM clock WHERE boot_id = ?", (now.boot_id,)).fetchone()
    base = float(row[0]) if row else boot_base(now, last_seen(cursor))
    return now.since_boot + base
