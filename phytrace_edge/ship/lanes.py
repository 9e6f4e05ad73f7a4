"""The two lanes that drain a backlog, and the link state that switches them.

The backfill sends the oldest events first (each hour's important events before its
periodic ones); the live lane sends the newest events queued since the link came back,
newest batch first. While a backlog drains, LIVE_SHARE of the requests are the live
lane's (when it has events), and the first request after an outage is, so PhyCloud
sees the robot's present within a round trip of the link coming back.
"""

from __future__ import annotations

import threading


class Lanes:
    """Whose turn the next request is, and whether requests are failing. Thread-safe:
    requests in flight report from their own threads."""

    def __init__(self, live_share: float, now: float) -> None:
        self._live_share = live_share
        self._lock = threading.Lock()
        self._live_since = now  # queue time since which events are the live lane's
        self._credit = 0.0  # grows by LIVE_SHARE per request; 1 buys a live one
        self._failed_at: float | None = None
        # the last request failed and is being retried; and before the first got
        # through, nothing says the link is up: until then requests are small probes
        self.failing = True

    def live_turn(self) -> float | None:
        """For a request of a backlog: ``since`` when it is the live lane's turn."""
        if self._live_share <= 0:
            return None
        with self._lock:
            self._credit += self._live_share
            if self._credit < 1.0:
                return None
            self._credit -= 1.0
            return self._live_since

    def failed(self, now: float) -> None:
        """A request failed at ``now`` (queue time)."""
        with self._lock:
            self.failing, self._failed_at = True, now

    def succeeded(self) -> None:
        """A request got through: after failures, the link is back. What was queued
        since the last failure is live, and the next request takes its newest."""
        with self._lock:
            if self.failing and self._failed_at is not None:
                self._live_since, self._credit = self._failed_at, 1.0
            self.failing = False
