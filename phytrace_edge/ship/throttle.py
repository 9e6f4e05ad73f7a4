"""Upload bandwidth cap (UPLOAD_MAX_BPS) for metered links: a token bucket over bytes."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class Throttle:
    """Waits before a send so that, on average, at most ``bytes_per_s`` go out; a burst
    of one second's worth is allowed. ``wait`` is interruptible by its ``sleep``, and
    may be called from several threads (requests in flight share the link)."""

    def __init__(
        self,
        bytes_per_s: int | None,
        sleep: Callable[[float], object],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.bytes_per_s = bytes_per_s
        self._sleep = sleep
        self._clock = clock
        self._tokens = float(bytes_per_s or 0)
        self._updated = clock()
        self._lock = threading.Lock()

    def wait(self, size: int) -> float:
        """Block until ``size`` bytes may be sent; the seconds waited."""
        if not self.bytes_per_s:
            return 0.0
        with self._lock:
            now = self._clock()
            capacity = float(self.bytes_per_s)
            self._tokens = min(capacity, self._tokens + (now - self._updated) * self.bytes_per_s)
            self._updated = now
            self._tokens -= size
            if self._tokens >= 0:
                return 0.0
            delay = -self._tokens / self.bytes_per_s
        self._sleep(delay)
        return delay
