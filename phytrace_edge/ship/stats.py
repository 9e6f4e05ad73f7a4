"""What status and metrics show about sending, kept by the sender."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

from phytrace_edge.errors import EndpointRefusedError, UnexpectedAnswerError

LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)
_INTERNAL = ("latency_buckets", "latency_count", "latency_sum_s", "lock")


@dataclass
class SendStats:
    """What status and metrics show about sending. Requests in flight update it from
    their threads: every change is made under ``lock`` (``update``)."""

    events_sent: int = 0
    batches_sent: int = 0
    bytes_sent: int = 0
    retries: int = 0
    batches_split: int = 0
    dead_lettered: int = 0
    auth_failures: int = 0
    unexpected_answers: int = 0
    last_success_at: float | None = None
    last_error: str | None = None
    last_error_class: str | None = None  # "HTTP 503", "ConnectError": no details, no key
    last_error_at: float | None = None
    last_status: int | None = None
    # a refusal only the operator can fix (TLS, a key, a proxy's credentials): status
    # is unhealthy with it until a request succeeds again
    last_refusal: str | None = None
    last_refusal_at: float | None = None
    live_events_sent: int = 0  # the live lane's: the newest first, after an outage
    backfill_events_sent: int = 0
    newest_delivered_at: float | None = None  # when the newest event PhyCloud has was queued
    queue_errors: int = 0
    last_queue_error: str | None = None
    last_queue_error_at: float | None = None
    latency_buckets: list[int] = field(default_factory=lambda: [0] * len(LATENCY_BUCKETS_S))
    latency_count: int = 0
    latency_sum_s: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def update(self, **changes: Any) -> None:
        """Set fields, and add to the counters named ``add_<field>``, at once."""
        with self.lock:
            for name, value in changes.items():
                if name.startswith("add_"):
                    setattr(self, name[4:], getattr(self, name[4:]) + value)
                else:
                    setattr(self, name, value)

    def delivered(self, lane: str, events: int, newest_queued_at: float) -> None:
        """Count a batch PhyCloud accepted, by lane (``live`` or ``backfill``)."""
        with self.lock:
            if lane == "live":
                self.live_events_sent += events
            else:
                self.backfill_events_sent += events
            newest = self.newest_delivered_at
            self.newest_delivered_at = max(newest or newest_queued_at, newest_queued_at)

    def failed(self, exc: BaseException | None, at: float) -> None:
        """Count an attempt that failed and will be retried, and remember why."""
        status = getattr(exc, "status", None)
        if isinstance(exc, EndpointRefusedError):
            self.update(last_refusal=str(exc), last_refusal_at=at)
        self.update(
            add_retries=1,
            last_error=str(exc),
            last_error_class=self.error_class(exc, status),
            last_error_at=at,
            last_status=status,
            add_unexpected_answers=int(isinstance(exc, UnexpectedAnswerError)),
            add_auth_failures=int(isinstance(exc, EndpointRefusedError) and status in (401, 403)),
        )

    def observe_latency(self, seconds: float) -> None:
        """Count one request's duration into the cumulative histogram."""
        with self.lock:
            self.latency_count += 1
            self.latency_sum_s += seconds
            for i, bound in enumerate(LATENCY_BUCKETS_S):
                if seconds <= bound:
                    self.latency_buckets[i] += 1

    @staticmethod
    def error_class(exc: BaseException | None, status: int | None) -> str | None:
        """What kind of failure ``exc`` is, in a word: the HTTP status PhyCloud
        answered, or the class of the network error under it."""
        if exc is None:
            return None
        if status is not None:
            return f"HTTP {status}"
        return type(exc.__cause__ or exc).__name__

    def as_dict(self) -> dict[str, Any]:
        with self.lock:
            return {k: v for k, v in vars(self).items() if k not in _INTERNAL}
