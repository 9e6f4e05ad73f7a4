"""The sender: drains the queue to PhyCloud in batches, never dropping data.

Each round claims the oldest batch under a lease, sends it, and acks it when PhyCloud
has it. Failures are retried with tenacity until they succeed or the sender is
stopped; only PhyCloud refusing an event as bad data dead-letters it:

- 2xx: ack; events PhyCloud refused individually go to dead letters.
- 400/422: split the batch (at the index PhyCloud blamed, else in halves) and send
  the parts, recursively, until the offending events are alone; dead-letter those.
- 413: split likewise; a single event still too large is dead-lettered.
- 408/425/429/5xx, timeouts, connection errors: retry, exponential backoff with full
  jitter between RETRY_MIN_S and RETRY_MAX_S, or Retry-After when the server says.
- 401/403/415 and unexpected answers: keep the data, retry at RETRY_MAX_S, log ERROR.

Full jitter is also what makes a fleet recover politely: after an outage each robot's
next attempt falls at a random point of its backoff window, so PhyCloud does not get
every robot's backlog in the same second.
"""

from __future__ import annotations

import contextlib
import logging
import random
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from tenacity import RetryCallState, Retrying, retry_if_exception_type, wait_random_exponential

from phytrace_edge.errors import (
    EndpointRefusedError,
    QueueError,
    TransientSendError,
    UnexpectedAnswerError,
)
from phytrace_edge.queue.records import Batch, DeadLetter, QueuedEvent
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.request import BodyEncoder, events_body, request_headers
from phytrace_edge.ship.responses import Accepted, Refused, classify
from phytrace_edge.ship.throttle import Throttle
from phytrace_edge.ship.transport import Transport

log = logging.getLogger(__name__)

RETRY_AFTER_JITTER = 0.2  # up to 20% later than asked, so a fleet told the same time spreads
POLL_INTERVAL_S = 0.25
QUEUE_RETRY_S = 1.0
BEAT_S = 1.0
LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)


@dataclass
class SendStats:
    """What status and metrics show about sending. Updated by the sender thread only."""

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
    last_error_at: float | None = None
    last_status: int | None = None
    queue_errors: int = 0
    last_queue_error: str | None = None
    last_queue_error_at: float | None = None
    latency_buckets: list[int] = field(default_factory=lambda: [0] * len(LATENCY_BUCKETS_S))
    latency_count: int = 0
    latency_sum_s: float = 0.0

    def observe_latency(self, seconds: float) -> None:
        """Count one request's duration into the cumulative histogram."""
        self.latency_count += 1
        self.latency_sum_s += seconds
        for i, bound in enumerate(LATENCY_BUCKETS_S):
            if seconds <= bound:
                self.latency_buckets[i] += 1

    def as_dict(self) -> dict[str, Any]:
        data = dict(vars(self))
        for key in ("latency_buckets", "latency_count", "latency_sum_s"):
            data.pop(key)
        return data


class Stopped(Exception):
    """The sender was asked to stop while a batch was still retrying."""


class Sender:
    """Ships the queue to PhyCloud; ``run`` in a thread, ``drain`` for the CLI."""

    def __init__(
        self,
        store: QueueStore,
        transport: Transport,
        policy: SendPolicy,
        *,
        stop: threading.Event | None = None,
        clock: Callable[[], float] = time.time,
        rng: random.Random | None = None,
        sleep: Callable[[float], object] | None = None,
    ) -> None:
        self.store = store
        self.transport = transport
        self.policy = policy
        self.stop = stop or threading.Event()
        self.flushing = threading.Event()  # shutting down: send partial batches at once
        self.stats = SendStats()
        self._clock = clock
        self._rng = rng or random.Random()
        self._pause = sleep or self._wait_beating
        self._beat: Callable[[], None] = lambda: None
        self._deadline: float | None = None
        self._throttle = Throttle(policy.upload_max_bps, self._sleep)
        self._encoder = BodyEncoder(policy.http_compression)
        # full jitter between RETRY_MIN_S and the exponential bound (never a tight loop)
        self._backoff = wait_random_exponential(
            multiplier=policy.retry_min_s, max=policy.retry_max_s, min=policy.retry_min_s
        )

    # ------------------------------------------------------------------ loops

    def run(self, beat: Callable[[], None] = lambda: None) -> None:
        """Send until ``stop`` is set; the backlog drains on a timer, not only when new
        events arrive. ``beat`` is called as the loop makes progress (and while it
        waits out a backoff), for the supervisor."""
        self._beat = beat
        while not self.stop.is_set():
            try:
                sent = self.send_next_batch(flush=self.flushing.is_set())
            except Stopped:
                return
            except QueueError as exc:  # busy, full: the queue will be usable again
                self._queue_trouble(exc)
                continue
            beat()
            if not sent:
                self.stop.wait(min(POLL_INTERVAL_S, self.policy.flush_interval_s))

    def drain(
        self, deadline: float | None = None, progress: Callable[[int], None] | None = None
    ) -> bool:
        """Send everything queued now, partial batches included; True when empty. A
        ``deadline`` (monotonic) also cuts short a batch that is still retrying."""
        self._deadline = deadline
        try:
            while not self.stop.is_set() and not self._past_deadline():
                try:
                    sent = self.send_next_batch(flush=True)
                except Stopped:
                    break
                except QueueError as exc:
                    self._queue_trouble(exc)
                    continue
                if progress is not None and sent:
                    progress(sent)
                if not sent and self.store.counter("depth") == 0:
                    return True
                if not sent:
                    self.stop.wait(POLL_INTERVAL_S)  # another process holds what is left
            return self.store.counter("depth") == 0
        finally:
            self._deadline = None

    def _queue_trouble(self, exc: QueueError) -> None:
        """The queue could not be read or written this time (another process holds the
        write lock, the disk is full): count it, say so now and then, and wait a bit."""
        self.stats.queue_errors += 1
        self.stats.last_queue_error = str(exc)
        self.stats.last_queue_error_at = self._clock()
        if self.stats.queue_errors in (1, 10) or self.stats.queue_errors % 100 == 0:
            log.error("cannot use the queue to send (%s); trying again", exc)
        self._sleep_quietly(QUEUE_RETRY_S)

    def _sleep_quietly(self, seconds: float) -> None:
        with contextlib.suppress(Stopped):
            self._sleep(seconds)

    def _past_deadline(self) -> bool:
        return self._deadline is not None and time.monotonic() >= self._deadline

    def due(self) -> bool:
        """Whether a batch should go now: a full batch waits, or the oldest event has
        waited FLUSH_INTERVAL_S."""
        depth, oldest = self.store.backlog()
        if depth == 0 or oldest is None:
            return False
        return depth >= self.policy.batch_size or (
            self._clock() - oldest >= self.policy.flush_interval_s
        )

    def send_next_batch(self, flush: bool = False) -> int:
        """Claim, send and ack one batch; the number of events it held (0: none due)."""
        if not flush and not self.due():
            return 0
        batch = self.store.claim_batch(self.policy.batch_size, self.policy.batch_max_bytes)
        if batch is None:
            return 0
        try:
            dead = self._deliver(batch, batch.events)
        except BaseException:  # stopped, or a failure the supervisor restarts us after
            with contextlib.suppress(QueueError):  # else the lease runs out by itself
                self.store.release(batch)
            raise
        self.store.ack(batch, dead)
        if dead:
            self.stats.dead_lettered += len(dead)
            log.error(
                "%d event(s) rejected by PhyCloud moved to dead letters (%s) - see "
                "phytrace-edge dead-letters list",
                len(dead),
                dead[0].reason,
            )
        return len(batch.events)

    # ------------------------------------------------------------------ delivery

    def _deliver(self, batch: Batch, events: Sequence[QueuedEvent]) -> list[DeadLetter]:
        """Get ``events`` into PhyCloud; the ones it refuses for good, as dead letters."""
        outcome = self._send_with_retries(batch, events)
        if isinstance(outcome, Accepted):
            return [
                DeadLetter(events[i].id, f"rejected: {reason}", None, reason)
                for i, reason in sorted(outcome.rejected.items())
            ]
        if len(events) == 1:
            return [
                DeadLetter(
                    events[0].id, f"rejected: HTTP {outcome.status}", outcome.status, outcome.reason
                )
            ]
        self.stats.batches_split += 1
        return [dead for part in _split(events, outcome) for dead in self._deliver(batch, part)]

    def _send_with_retries(self, batch: Batch, events: Sequence[QueuedEvent]) -> Accepted | Refused:
        body = events_body(events)
        encoded = self._encoder.encode(body)
        headers = request_headers(events, self.policy.http_compression)
        retrying = Retrying(
            retry=retry_if_exception_type(TransientSendError),
            wait=self._wait,
            sleep=self._sleep,
            before_sleep=lambda state: self._before_retry(batch, state),
            reraise=True,
        )
        for attempt in retrying:
            with attempt:
                if self.stop.is_set():
                    raise Stopped
                self._throttle.wait(len(encoded))
                started = time.monotonic()
                reply = self.transport.post_events(encoded, headers)
                outcome = classify(reply, len(events), self._clock())
                self.stats.observe_latency(time.monotonic() - started)
                self._record_success(len(events), len(encoded), reply.status)
                return outcome
        raise AssertionError("tenacity returns or raises")

    def _wait(self, state: RetryCallState) -> float:
        """Retry-After when the server gave one (plus a little jitter); RETRY_MAX_S for
        refusals data cannot fix; else exponential backoff with full jitter."""
        exc = state.outcome.exception() if state.outcome else None
        if isinstance(exc, EndpointRefusedError):
            return self.policy.retry_max_s
        if isinstance(exc, TransientSendError) and exc.retry_after is not None:
            # never sooner than RETRY_MIN_S: "Retry-After: 0", a negative number or a
            # date in the past (a robot whose clock runs ahead) would make a tight loop
            wait = max(exc.retry_after, self.policy.retry_min_s)
            return wait * (1 + RETRY_AFTER_JITTER * self._rng.random())
        return float(self._backoff(state))

    def _wait_beating(self, seconds: float) -> None:
        """Wait ``seconds`` or until stopped, beating at least once a second."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0 and not self.stop.wait(min(left, BEAT_S)):
            self._beat()

    def _sleep(self, seconds: float) -> None:
        """Sleep, but wake up at once when asked to stop or at the drain's deadline."""
        if self._deadline is not None:
            seconds = min(seconds, max(0.0, self._deadline - time.monotonic()))
        self._pause(seconds)
        if self.stop.is_set() or self._past_deadline():
            raise Stopped

    def _before_retry(self, batch: Batch, state: RetryCallState) -> None:
        exc = state.outcome.exception() if state.outcome else None
        self.stats.retries += 1
        self.stats.last_error = str(exc)
        self.stats.last_error_at = self._clock()
        self.stats.last_status = getattr(exc, "status", None)
        if isinstance(exc, UnexpectedAnswerError):
            self.stats.unexpected_answers += 1
        if isinstance(exc, EndpointRefusedError):
            if exc.status in (401, 403):
                self.stats.auth_failures += 1
            log.error(
                "%s; keeping the queued events, retrying in %.0f s", exc, state.upcoming_sleep
            )
        elif state.attempt_number == 1 or state.attempt_number % 10 == 0:
            log.warning(
                "send failed (%s), attempt %d; retrying in %.1f s",
                exc,
                state.attempt_number,
                state.upcoming_sleep,
            )
        with contextlib.suppress(QueueError):  # a lease that runs out only means a resend
            self.store.renew(batch)

    def _record_success(self, events: int, size: int, status: int) -> None:
        if 200 <= status < 300:
            self.stats.events_sent += events
            self.stats.batches_sent += 1
            self.stats.bytes_sent += size
            self.stats.last_success_at = self._clock()
        self.stats.last_status = status


def _split(events: Sequence[QueuedEvent], refused: Refused) -> list[Sequence[QueuedEvent]]:
    """Parts to resend: around the event PhyCloud blamed, else two halves."""
    if refused.index is not None and refused.status != 413:
        i = refused.index
        return [part for part in (events[:i], events[i : i + 1], events[i + 1 :]) if part]
    middle = len(events) // 2
    return [events[:middle], events[middle:]]
