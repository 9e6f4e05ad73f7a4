"""QueueWriter: events from the sample tick into the queue, on a thread of their own.

The tick runs on the ROS executor; an fsync on slow robot flash can take tens of
milliseconds, and ingest must never wait for it. The tick hands the event over in
memory (microseconds); the writer thread puts whatever has accumulated in one
transaction (group commit). The hand-off is bounded: if the disk stalls so long that
it fills, the newest events are counted as dropped (``writer_backlog``) and logged,
rather than memory growing.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import Any

from phytrace_edge.errors import QueueError
from phytrace_edge.queue import QueueStore

log = logging.getLogger(__name__)

HANDOFF_MAX_EVENTS = 10_000
GROUP_MAX_EVENTS = 500
RETRY_S = 0.5


class QueueWriter:
    def __init__(self, store: QueueStore) -> None:
        self.store = store
        self._pending: deque[dict[str, Any]] = deque()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._retry_pause = threading.Event()  # never set: a plain interruptible pause
        self._thread = threading.Thread(target=self._run, name="queue-writer", daemon=True)
        self.events_dropped = 0

    def start(self) -> None:
        self._thread.start()

    def put(self, event: dict[str, Any]) -> None:
        """Hand an event over; never blocks on disk."""
        with self._lock:
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
            self._pending.append(event)
        self._wake.set()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Write what was handed over, then stop."""
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout_s)

    def alive(self) -> bool:
        return self._thread.is_alive()

    def backlog(self) -> int:
        with self._lock:
            return len(self._pending)

    def _run(self) -> None:
        while True:
            self._wake.wait()
            self._wake.clear()
            while self._write_group():
                pass
            if self._stop.is_set() and not self.backlog():
                return

    def _write_group(self) -> bool:
        """Put up to GROUP_MAX_EVENTS pending events; False when none were pending."""
        with self._lock:
            group = [self._pending[i] for i in range(min(GROUP_MAX_EVENTS, len(self._pending)))]
        if not group:
            return False
        try:
            self.store.put_many(group)  # drops by the caps are counted by the store
        except QueueError as exc:  # busy past the timeout: keep them and try again
            log.warning("queue put failed (%s); retrying in %.1f s", exc, RETRY_S)
            self._retry_pause.wait(RETRY_S)
            return True
        with self._lock:
            for _ in group:
                self._pending.popleft()
        return True
