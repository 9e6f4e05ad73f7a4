"""QueueWriter: events from the sample tick into the queue, on a thread of their own.

The tick must never wait for the disk: an fsync on slow robot flash can take tens of
milliseconds. The tick hands the event over in memory (microseconds); the writer's
loop puts whatever has accumulated in one transaction (group commit). The hand-off is
bounded: if the disk stalls so long that it fills, a live input's newest events are
counted as dropped (``writer_backlog``, shown by ``status``) and logged, rather than
memory growing. A replayed bag waits instead (``put(wait=True)``): it can go no faster
than the disk, and nothing of it need be lost.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

from phytrace_edge.builder.builder import Built
from phytrace_edge.errors import QueueError
from phytrace_edge.queue.store import QueueStore

log = logging.getLogger(__name__)

HANDOFF_MAX_EVENTS = 10_000
GROUP_MAX_EVENTS = 500
RETRY_S = 0.5
IDLE_BEAT_S = 1.0


class QueueWriter:
    """``put`` from any thread; ``run`` is the writer's loop (supervised)."""

    def __init__(self, store: QueueStore) -> None:
        self.store = store
        self.stop = threading.Event()
        self._pending: deque[Built] = deque()
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)
        self._wake = threading.Event()
        self._retry_pause = threading.Event()  # never set: a plain interruptible pause
        self.events_dropped = 0

    def put(self, built: Built, wait: bool = False) -> None:
        """Hand an event over; never blocks on disk unless asked to ``wait`` for room
        (it then returns early only when the writer is stopping)."""
        with self._lock:
            while wait and len(self._pending) >= HANDOFF_MAX_EVENTS and not self.stop.is_set():
                self._room.wait(RETRY_S)
            if len(self._pending) >= HANDOFF_MAX_EVENTS:
                self.events_dropped += 1
                if self.events_dropped in (1, 100) or self.events_dropped % 10_000 == 0:
                    log.error(
                        "queue writer is %d events behind the disk: dropping new events "
                        "(%d so far)",
                        HANDOFF_MAX_EVENTS,
                        self.events_dropped,
                    )
                return
            self._pending.append(built)
        self._wake.set()

    def request_stop(self) -> None:
        """Write what was handed over, then let ``run`` return."""
        self.stop.set()
        self._wake.set()

    def backlog(self) -> int:
        with self._lock:
            return len(self._pending)

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Write what is handed over until ``stop`` (this writer's ``stop``, lent to
        its worker), then what is left."""
        while True:
            self._wake.wait(IDLE_BEAT_S)
            self._wake.clear()
            while self._write_group():
                beat()
            beat()
            if stop.is_set() and not self.backlog():
                return

    def _write_group(self) -> bool:
        """Put up to GROUP_MAX_EVENTS pending events; False when none were pending."""
        with self._lock:
            group = [self._pending[i] for i in range(min(GROUP_MAX_EVENTS, len(self._pending)))]
        if not group:
            return False
        try:
            # drops by the caps are counted by the store
            self.store.put_many([b.event for b in group], [b.important for b in group])
        except QueueError as exc:  # busy past the timeout: keep them and try again
            log.warning("queue put failed (%s); retrying in %.1f s", exc, RETRY_S)
            self._retry_pause.wait(RETRY_S)
            return True
        with self._lock:
            for _ in group:
                self._pending.popleft()
            self._room.notify_all()
        return True
