"""What status and metrics show about sending, kept by the sender."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, fields
from typing import Any

from phytrace_edge.errors import EndpointRefusedError, UnexpectedAnswerError

LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)
_INTERNAL = ("latency_buckets", "latency_count", "latency_sum_s", "lock")


@dataclass(slots=True)
class SendStats:
    """What status and metrics show about sending. Requests in flight update it from
    their threads: every change is made by a method here, under ``lock``."""

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
    incident_parts_sent: int = 0  # ``incident`` events PhyCloud accepted
    incident_parts_dead_lettered: int = 0
    newest_delivered_at: float | None = None  # when the newest event PhyCloud has was queued
    queue_errors: int = 0
    last_queue_error: str | None = None
    last_queue_error_at: float | None = None
    latency_buckets: list[int] = field(default_factory=lambda: [0] * len(LATENCY_BUCKETS_S))
    latency_count: int = 0
    latency_sum_s: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def add_sent(self, events: int, body_bytes: int, status: int, at: float) -> None:
        """Count a request PhyCloud answered with a 2xx that accounts for its events."""
        with self.lock:
            self.events_sent += events
            self.batches_sent += 1
            self.bytes_sent += body_bytes
            self.last_success_at = at
            self.last_status = status

    def set_status(self, status: int) -> None:
        """Remember the status of an answer that is final but no success (a refusal
        of bad data, dead-lettered or split)."""
        with self.lock:
            self.last_status = status

    def delivered(self, lane: str, events: int, newest_queued_at: float) -> None:
        """Count a batch PhyCloud accepted, by lane (``live`` or ``backfill``)."""
        with self.lock:
            if lane == "live":
                self.live_events_sent += events
            else:
                self.backfill_events_sent += events
            newest = self.newest_delivered_at
            self.newest_delivered_at = max(newest or newest_queued_at, newest_queued_at)

    def add_dead_lettered(self, events: int) -> None:
        """Count events PhyCloud refused for good, moved to dead letters."""
        with self.lock:
            self.dead_lettered += events

    def incident_parts(self, sent: int, dead_lettered: int) -> None:
        """Count the ``incident`` events of a batch PhyCloud answered."""
        with self.lock:
            self.incident_parts_sent += sent
            self.incident_parts_dead_lettered += dead_lettered

    def count_split(self) -> None:
        """Count a batch split in two or more parts (refused, too large, unaccounted)."""
        with self.lock:
            self.batches_split += 1

    def count_retry(self, exc: BaseException | None, at: float) -> None:
        """Count an attempt that failed and will be retried, and remember why."""
        status = getattr(exc, "status", None)
        with self.lock:
            self.retries += 1
            if isinstance(exc, EndpointRefusedError):
                self.last_refusal, self.last_refusal_at = str(exc), at
                if status in (401, 403):
                    self.auth_failures += 1
            if isinstance(exc, UnexpectedAnswerError):
                self.unexpected_answers += 1
            self.last_error = str(exc)
            self.last_error_class = self.error_class(exc, status)
            self.last_error_at = at
            self.last_status = status

    def count_queue_error(self, exc: BaseException, at: float) -> int:
        """Count a time the queue could not be used to send; how many times so far."""
        with self.lock:
            self.queue_errors += 1
            self.last_queue_error, self.last_queue_error_at = str(exc), at
            return self.queue_errors

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
        """The figures status and metrics show (``SenderFigures``), at one moment."""
        with self.lock:
            return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in _INTERNAL}
