"""QueueWriter: where built events leave the pipeline, into the queue, on a thread of
their own.

``emit`` is where the sampler and the health events hand a built event over: it is
checked against the UDM schema (a violation is logged and the event still kept),
counted, shown to an observer (the tests) and queued for the writer's thread.

The tick must never wait for the disk: an fsync on slow robot flash can take tens of
milliseconds, a failing SD card seconds. The tick hands the event over in memory
(microseconds); the writer's loop puts whatever has accumulated in one transaction
(group commit).

While the queue cannot be written (an I/O error, a read-only or vanished volume), the
events wait here, in memory, up to ``HANDOFF_MAX_EVENTS``, and are written when the
volume works again. Beyond that bound a live input's newest events are dropped and
counted (``writer_backlog``); a replayed bag waits instead (``put(wait=True)``): it can
go no faster than the disk, and nothing of it need be lost. At a stop, what still
could not be written by the deadline is counted as ``unwritable``. Every count goes
into the queue's own counters (``QueueStore.count_unqueued``), so that events built =
delivered + queued + dead-lettered + dropped by reason, whatever the disk did.

``figures()`` says how the disk is doing (``StorageFigures``): how long writes have
failed and why, how many events wait in memory and for how long, and how long commits
take; ``status`` names a failing or slow disk from them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.peek import QueueStats
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime.status_documents import LedgerFigures, WriterFigures
from phytrace_edge.udm.schema import check_event
from phytrace_edge.udm.types import Built, UdmEvent

log = logging.getLogger(__name__)

HANDOFF_MAX_EVENTS = 10_000
GROUP_MAX_EVENTS = 500
RETRY_S = 0.5
IDLE_BEAT_S = 1.0
REPORT_EVERY_S = 30.0  # a failing disk: the first error, then a summary this often
COMMIT_WINDOW_S = 60.0  # the slowest commit is remembered this long
STOP_WITHIN_S = 10.0


@dataclass
class _Failing:
    """Queue writes that keep failing: since when, how often, the last reason."""

    since: float  # monotonic
    attempts: int = 0
    last_error: str = ""
    reported_at: float = 0.0


@dataclass
class _Commits:
    """How long the writer's commits take: the last one and the slowest lately."""

    last_s: float | None = None
    slowest: deque[tuple[float, float]] = field(default_factory=deque)  # (at, seconds)

    def record(self, seconds: float, now: float) -> None:
        self.last_s = seconds
        # a window maximum: a commit hides the faster ones before it
        while self.slowest and self.slowest[-1][1] <= seconds:
            self.slowest.pop()
        self.slowest.append((now, seconds))

    def slowest_s(self, now: float) -> float | None:
        while self.slowest and self.slowest[0][0] < now - COMMIT_WINDOW_S:
            self.slowest.popleft()
        return self.slowest[0][1] if self.slowest else None


class QueueWriter:
    """``emit`` (or ``put``) from any thread; ``run`` is the writer's loop (supervised).

    With ``wait_for_disk`` (an input that keeps its own time, a bag) ``emit`` waits for
    room instead of outrunning the disk; ``on_event`` sees every event emitted."""

    def __init__(
        self,
        store: QueueStore,
        monotonic: Callable[[], float] = time.monotonic,
        wait_for_disk: bool = False,
        on_event: Callable[[UdmEvent], None] | None = None,
    ) -> None:
        self.store = store
        self.wait_for_disk = wait_for_disk
        self._on_event = on_event
        self.stop = threading.Event()
        self._monotonic = monotonic
        self._pending: deque[tuple[float, Built]] = deque()  # (handed over at, event)
        self._in_hand = 0  # taken from _pending, being written
        self._in_hand_since = 0.0  # when the first of those was handed over
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)
        self._wake = threading.Event()
        self._deadline: float | None = None  # monotonic: stop writing then (a stop)
        self._finished = False  # stopped: what is handed over now is never written
        self._failing: _Failing | None = None
        self._commits = _Commits()
        self.events_handed = 0
        self.events_written = 0
        self.dropped: Counter[str] = Counter()

    def emit(self, built: Built) -> None:
        """Hand over an event as it leaves the pipeline (see the module doc)."""
        check_event(built.event, log)
        if self._on_event is not None:
            self._on_event(built.event)
        self.put(built, wait=self.wait_for_disk)

    def put(self, built: Built, wait: bool = False) -> None:
        """Hand an event over; never blocks on disk unless asked to ``wait`` for room
        (it then returns early only when the writer is stopping)."""
        with self._lock:
            while wait and len(self._pending) >= HANDOFF_MAX_EVENTS and not self.stop.is_set():
                self._room.wait(RETRY_S)
            self.events_handed += 1
            if self._finished:  # after the stop: nothing will write it
                self._drop_locked("unwritable", 1)
                return
            if len(self._pending) >= HANDOFF_MAX_EVENTS:
                self._drop_locked("writer_backlog", 1)
                return
            self._pending.append((self._monotonic(), built))
        self._wake.set()

    def request_stop(self, within_s: float = STOP_WITHIN_S) -> None:
        """Write what was handed over, then let ``run`` return; what is not written
        within ``within_s`` is counted as ``unwritable``."""
        self._deadline = self._monotonic() + within_s
        self.stop.set()
        self._wake.set()
        with self._lock:
            self._room.notify_all()

    def backlog(self) -> int:
        """Events handed over and not yet in the queue."""
        with self._lock:
            return len(self._pending) + self._in_hand

    def ledger(self) -> LedgerFigures:
        """This run's events at one moment: handed over = written + waiting + dropped."""
        with self._lock:
            return self._ledger_locked()

    def snapshot(self, wait_s: float = -1) -> tuple[QueueStats, LedgerFigures] | None:
        """The queue's figures and this run's ledger at one and the same moment, so
        that built = delivered + queued + dropped + in memory holds exactly; None when
        the queue's lock was not free within ``wait_s`` (a commit on a slow disk)."""
        lock = self.store.locked()
        if not lock.acquire(timeout=wait_s):
            return None
        try:
            with self._lock:  # the order a put's commit takes them
                return self.store.stats(), self._ledger_locked()
        finally:
            lock.release()

    def _ledger_locked(self) -> LedgerFigures:
        return {
            "built": self.events_handed,
            "written": self.events_written,
            "in_memory": len(self._pending) + self._in_hand,
            "dropped": dict(self.dropped),
        }

    def figures(self) -> WriterFigures:
        """How the disk is doing, for ``status`` and the metrics."""
        now = self._monotonic()
        with self._lock:
            # the group being committed waited longest: a slow commit is a wait too
            oldest = self._in_hand_since if self._in_hand else None
            if oldest is None and self._pending:
                oldest = self._pending[0][0]
            backlog = len(self._pending) + self._in_hand
        failing = self._failing
        return {
            "backlog": backlog,
            "backlog_max": HANDOFF_MAX_EVENTS,
            "oldest_backlog_age_s": None if oldest is None else round(now - oldest, 1),
            "writes_failing_s": None if failing is None else round(now - failing.since, 1),
            "write_attempts_failed": 0 if failing is None else failing.attempts,
            "last_write_error": None if failing is None else failing.last_error,
            "commit_s": _rounded(self._commits.last_s),
            "commit_max_s": _rounded(self._commits.slowest_s(now)),
        }

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Write what is handed over until ``stop`` (this writer's ``stop``, lent to
        its worker), then what is left, until the stop's deadline."""
        while True:
            self._wake.wait(IDLE_BEAT_S)
            self._wake.clear()
            while not self._past_deadline() and self._write_group():
                beat()
            beat()
            if stop.is_set() and (not self.backlog() or self._past_deadline()):
                self._give_up_on_the_rest()
                return

    def _past_deadline(self) -> bool:
        if self._deadline is None and self.stop.is_set():  # stopped without request_stop
            self._deadline = self._monotonic() + STOP_WITHIN_S
        return self._deadline is not None and self._monotonic() >= self._deadline

    def _write_group(self) -> bool:
        """Put up to GROUP_MAX_EVENTS pending events; False when none were pending."""
        with self._lock:
            count = min(GROUP_MAX_EVENTS, len(self._pending))
            handed = [self._pending.popleft() for _ in range(count)]
            self._in_hand = count
            if handed:
                self._in_hand_since = handed[0][0]
        if not handed:
            return False
        group = [built for _, built in handed]
        started = self._monotonic()

        def written() -> None:  # under the queue's lock: the ledger and the queue agree
            with self._lock:
                self.events_written += count
                self._in_hand = 0
                self._room.notify_all()

        try:
            # drops by the caps, and an event that cannot be encoded, are counted by
            # the store
            self.store.put_many(
                group,
                after_commit=written,
                upkeep=not self.stop.is_set(),  # a stop: no fsyncs beyond the events' own
            )
        except QueueError as exc:  # keep them, in order, and try again
            with self._lock:
                self._pending.extendleft(reversed(handed))  # with their hand-off times
                self._in_hand = 0
            self._failed(exc)
            # a pause, not a hand-shake: after a stop the writer still retries until
            # the deadline, and a wait on the set ``stop`` would make that a busy loop
            remaining = RETRY_S if self._deadline is None else self._deadline - started
            time.sleep(max(0.0, min(RETRY_S, remaining)))
            return True
        finished = self._monotonic()
        self._commits.record(finished - started, finished)
        self._recovered()
        return True

    def _failed(self, exc: QueueError) -> None:
        """A failed write: the first is logged at once, then a summary every
        REPORT_EVERY_S rather than a line per attempt."""
        now = self._monotonic()
        failing = self._failing
        if failing is None:
            failing = self._failing = _Failing(since=now, reported_at=now)
            log.error(
                "queue writes fail (%s); %d event(s) wait in memory (at most %d) and are "
                "written when the queue works again",
                exc,
                self.backlog(),
                HANDOFF_MAX_EVENTS,
            )
        elif now - failing.reported_at >= REPORT_EVERY_S:
            failing.reported_at = now
            log.error(
                "queue writes have failed for %.0f s (%d attempts; last: %s); %d event(s) "
                "wait in memory (at most %d), %d dropped so far",
                now - failing.since,
                failing.attempts + 1,
                exc,
                self.backlog(),
                HANDOFF_MAX_EVENTS,
                self.dropped["writer_backlog"],
            )
        failing.attempts += 1
        failing.last_error = str(exc)

    def _recovered(self) -> None:
        failing, self._failing = self._failing, None
        if failing is not None:
            log.warning(
                "queue writes work again after %.0f s (%d failed attempts); %d event(s) "
                "still wait in memory",
                self._monotonic() - failing.since,
                failing.attempts,
                self.backlog(),
            )

    def abandon(self) -> None:
        """The stop cannot wait for the writer any longer (a commit hangs on the disk):
        what waits in memory is counted as ``unwritable``. The group being committed is
        left to its commit (it is in the queue if that finishes before the exit)."""
        self._give_up_on_the_rest()

    def _give_up_on_the_rest(self) -> None:
        """At a stop: count what could not be written by the deadline."""
        with self._lock:
            self._finished = True
            left = len(self._pending)
            self._pending.clear()
            if left:
                self._drop_locked("unwritable", left)
            self._room.notify_all()
        if left:
            log.error(
                "%d event(s) could not be written to the queue before the stop (%s); "
                "counted as dropped (unwritable)",
                left,
                self._failing.last_error if self._failing else "the disk is too slow",
            )

    def _drop_locked(self, reason: str, count: int) -> None:
        """Count ``count`` events that will never reach the queue (the lock is held)."""
        self.dropped[reason] += count
        self.store.count_unqueued(reason, count)
        if reason == "writer_backlog":
            dropped = self.dropped[reason]
            if dropped in (1, 100) or dropped % 10_000 == 0:
                log.error(
                    "queue writer is %d events behind the disk: dropping new events (%d so far)",
                    HANDOFF_MAX_EVENTS,
                    dropped,
                )


def _rounded(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds, 3)
