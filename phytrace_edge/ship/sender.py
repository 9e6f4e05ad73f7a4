"""The sender: drains the queue to PhyCloud in batches, never dropping data.

Each batch is claimed under a lease, sent, and acked when PhyCloud has it. Failures
are retried with tenacity until they succeed or the sender is stopped; only PhyCloud
refusing an event as bad data dead-letters it:

- 2xx that accounts for every event (``responses.account``): ack; events PhyCloud
  refused individually go to dead letters.
- 2xx that does not: nothing acked or dead-lettered; retry with backoff. After
  UNACCOUNTED_BEFORE_SPLIT in a row, halve the batch and send the parts, down to single
  events; a single event is kept and retried every RETRY_MAX_S until it adds up.
- 400/422: split the batch (at the index PhyCloud blamed, else in halves) and send
  the parts, recursively, until the offending events are alone; dead-letter those.
- 413: split likewise; a single event still too large is dead-lettered.
- 408/425/429/5xx, timeouts, connection errors, a 2xx without PhyCloud's answer (a
  captive portal): retry with backoff, or Retry-After when the server says.
- 401/403/415 and other statuses: keep the data, retry at RETRY_MAX_S, log ERROR.

How long and how loudly: ``retries``.

Batches are pipelined (docs/phycloud-api.md, "Batches"): the sender's thread claims
and encodes the next batch while up to REQUESTS_IN_FLIGHT requests are on the wire,
each in a thread of its own that retries, acks or releases its batch. Every batch
has its own lease and idempotency key, so two in flight never hold the same event.
A live batch is BATCH_SIZE events; when more wait, requests grow to BACKLOG_BATCH_SIZE
events (or BATCH_MAX_BYTES of compressed body), in two lanes (``lanes``): the newest
first after an outage. A batch claimed before a step of the wall clock goes back and
is sent again with its stamps repaired (``Restamped``; queue/timekeeping/repair.py).
"""

from __future__ import annotations

import contextlib
import logging
import random
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple

from tenacity import RetryCallState, Retrying, retry_if_exception_type

from phytrace_edge.errors import QueueError, TransientSendError, UnaccountedAnswerError
from phytrace_edge.queue.records import Batch, DeadLetter, QueuedEvent
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.ship.lanes import Lanes
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.responses import Accepted, Outcome, classify, split_refused
from phytrace_edge.ship.retries import UNACCOUNTED_BEFORE_SPLIT, Backoff, say_halving, say_retrying
from phytrace_edge.ship.stats import SendStats
from phytrace_edge.ship.throttle import Throttle
from phytrace_edge.ship.transport import (
    BodyEncoder,
    Prepared,
    Transport,
    events_body,
    request_headers,
)
from phytrace_edge.udm.event import is_event_type

log = logging.getLogger(__name__)

POLL_INTERVAL_S = 0.25
QUEUE_RETRY_S = 1.0
BEAT_S = 1.0
# JSON claimed per byte of BATCH_MAX_BYTES when compressing: telemetry compresses 8-15x,
# so a batch claimed at 4x still fits; one that does not is halved before it is sent
JSON_PER_WIRE_BYTE = 4


class Due(NamedTuple):
    """Whether a batch should go now, and how many events wait."""

    now: bool
    depth: int


class Restamped(Exception):
    """The wall clock stepped after the batch was claimed: send it again, repaired."""


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
        clock: Callable[[], float] | None = None,
        rng: random.Random | None = None,
        sleep: Callable[[float], object] | None = None,
    ) -> None:
        self.store = store
        self.transport = transport
        self.policy = policy
        self.stop = stop or threading.Event()
        self.flushing = threading.Event()  # shutting down: send partial batches at once
        self.stats = SendStats()
        # the store's clock (queue time): the sender's times are compared with its rows'
        self._clock = clock or store.now
        self._rng = rng or random.Random()  # the jitter of every backoff
        # how a wait is spent (tests pass ``sleep`` to record them): on ``stop``, beating
        self._spend_wait: Callable[[float], object] = sleep or self._wait_beating
        self._beat: Callable[[], None] = lambda: None
        self._deadline: float | None = None
        self._throttle = Throttle(policy.upload_max_bps, self._wait_or_stop)
        self._encoders = threading.local()  # python-zstandard: one compressor per thread
        self._lanes = Lanes(policy.live_share, store.now())
        self._backoff = Backoff(policy, self._rng)

    # ------------------------------------------------------------------ loops

    def run(self, stop: threading.Event, beat: Callable[[], None] = lambda: None) -> None:
        """Send until ``stop`` is set (this sender's ``stop``, lent to its worker); the
        backlog drains on a timer, not only when new events arrive. ``beat`` is called
        as the loop makes progress (and while it waits out a backoff), for the
        supervisor."""
        assert stop is self.stop, "the sender waits on its own stop event"
        self._beat = beat
        self._pipeline(drain=False)

    def drain(
        self, deadline: float | None = None, progress: Callable[[int], None] | None = None
    ) -> bool:
        """Send everything queued now, partial batches included; True when empty. A
        ``deadline`` (monotonic) also cuts short a batch that is still retrying."""
        self._deadline = deadline
        try:
            self._pipeline(drain=True, progress=progress)
            return self.store.counter("depth") == 0
        finally:
            self._deadline = None

    def _pipeline(self, drain: bool, progress: Callable[[int], None] | None = None) -> None:
        """Claim and encode batches in this thread, and post them from up to
        REQUESTS_IN_FLIGHT others: the next batch is ready when a request returns."""
        in_flight: deque[Future[int]] = deque()
        with ThreadPoolExecutor(self.policy.requests_in_flight, "phytrace-post") as posts:
            try:
                while not self.stop.is_set() and not self._past_deadline():
                    try:
                        prepared = self.prepare_next(flush=drain or self.flushing.is_set())
                    except QueueError as exc:  # busy, full: the queue will be usable again
                        # an ack of what is on the wire may be what frees the disk
                        self._queue_trouble(exc, pause=not in_flight)
                        if in_flight:
                            self._settle(in_flight.popleft(), progress)
                        continue
                    if prepared is None:
                        if in_flight:  # what is on the wire may free the rest
                            self._settle(in_flight.popleft(), progress)
                        elif drain and self.store.counter("depth") == 0:
                            return
                        else:  # nothing due, or another process holds what is left
                            # idle is alive: a quiet robot is no stalled sender
                            self._wait_beating(min(POLL_INTERVAL_S, self.policy.flush_interval_s))
                        continue
                    # while requests fail, one at a time: an outage is not hit twice as often
                    limit = 1 if self._lanes.failing else self.policy.requests_in_flight
                    try:
                        while len(in_flight) >= limit:
                            self._settle(in_flight.popleft(), progress)
                    except BaseException:  # claimed, never sent: back at once, not after its lease
                        with contextlib.suppress(QueueError):
                            self.store.release(prepared.batch)
                        raise
                    in_flight.append(posts.submit(self.post, prepared))
                    self._beat()
            finally:
                while in_flight:
                    self._settle(in_flight.popleft(), progress)

    def _settle(self, future: Future[int], progress: Callable[[int], None] | None) -> None:
        """Wait for a request in flight; its failures surface here, in the sender's
        thread (a stop is no failure; a queue error pauses)."""
        try:
            sent = future.result()
        except Stopped:
            return
        except QueueError as exc:
            self._queue_trouble(exc)
            return
        self._beat()
        if progress is not None and sent:
            progress(sent)

    def _queue_trouble(self, exc: QueueError, pause: bool = True) -> None:
        """The queue could not be read or written this time (another process holds the
        write lock, the disk is full): count it, say so now and then, and wait a bit."""
        errors = self.stats.count_queue_error(exc, self._clock())
        if errors in (1, 10) or errors % 100 == 0:
            log.error("cannot use the queue to send (%s); trying again", exc)
        if pause:
            with contextlib.suppress(Stopped):  # the loop sees the stop itself
                self._wait_or_stop(QUEUE_RETRY_S)

    def _past_deadline(self) -> bool:
        return self._deadline is not None and time.monotonic() >= self._deadline

    # ------------------------------------------------------------------ one batch

    def due(self) -> Due:
        """Whether a batch should go now (a full batch waits, or the oldest event has
        waited FLUSH_INTERVAL_S), and the events waiting."""
        depth, oldest = self.store.backlog()
        if depth == 0 or oldest is None:
            return Due(now=False, depth=depth)
        waited = self._clock() - oldest >= self.policy.flush_interval_s
        return Due(now=depth >= self.policy.batch_size or waited, depth=depth)

    def prepare_next(self, flush: bool = False) -> Prepared | None:
        """Claim the next batch and encode it; None when no batch is due."""
        due = self.due()
        if not flush and not due.now:
            return None
        depth = due.depth
        policy = self.policy
        # a backlog goes in big requests, but not while requests fail: a probe of a live
        # batch finds out whether the link is back without holding a megabyte
        backlog = depth > policy.batch_size and not self._lanes.failing
        size = max(policy.backlog_batch_size, policy.batch_size) if backlog else policy.batch_size
        compressed = policy.http_compression != "none"
        json_bound = policy.batch_max_bytes * (JSON_PER_WIRE_BYTE if compressed else 1)
        lane, batch = self._claim(size, json_bound, depth)
        if batch is None:
            return None
        body = self._encoder().encode(events_body(batch.events))
        headers = request_headers(batch.events, policy.http_compression)
        return Prepared(batch, body, headers, lane)

    def _claim(self, size: int, json_bound: int, depth: int) -> tuple[str, Batch | None]:
        """The next batch and its lane: the live lane's turn comes LIVE_SHARE of the
        time while a backlog drains (and at once after an outage); else the backfill."""
        since = self._lanes.live_turn() if depth > self.policy.batch_size else None
        if since is not None:
            batch = self.store.claim_live(size, json_bound, since)
            if batch is not None:
                return "live", batch
        return "backfill", self.store.claim_batch(size, json_bound, self.policy.important_first)

    def post(self, prepared: Prepared) -> int:
        """Deliver a prepared batch and ack it; the number of events it held. Released
        (not lost) when the sender stops or fails while it retries."""
        batch = prepared.batch
        try:
            with contextlib.suppress(QueueError):  # it waited its turn: a fresh lease
                self.store.renew(batch)
            dead = self._deliver(batch, batch.events, prepared)
        except Restamped:
            self.store.release(batch)
            return 0
        except BaseException:  # stopped, or a failure the supervisor restarts us after
            with contextlib.suppress(QueueError):  # else the lease runs out by itself
                self.store.release(batch)
            raise
        self.store.ack(batch, dead)
        newest = max(event.queued_at for event in batch.events)
        self.stats.delivered(prepared.lane, len(batch.events), newest)
        refused = {letter.queue_id for letter in dead}
        incidents = [e.id in refused for e in batch.events if is_event_type(e.json, "incident")]
        if incidents:
            self.stats.incident_parts(incidents.count(False), incidents.count(True))
        if dead:
            self.stats.add_dead_lettered(len(dead))
            log.error(
                "%d event(s) rejected by PhyCloud moved to dead letters (%s) - see "
                "phytrace-edge dead-letters list",
                len(dead),
                dead[0].reason,
            )
        return len(batch.events)

    # ------------------------------------------------------------------ delivery

    def _deliver(
        self, batch: Batch, events: Sequence[QueuedEvent], prepared: Prepared | None = None
    ) -> list[DeadLetter]:
        """Get ``events`` into PhyCloud; the ones it refuses for good, as dead letters."""
        body = prepared.body if prepared else self._encoder().encode(events_body(events))
        if len(body) > self.policy.batch_max_bytes and len(events) > 1:
            return self._halve(batch, events)  # larger than BATCH_MAX_BYTES
        headers = prepared.headers if prepared else request_headers(events, self._encoding)
        outcome = self._send_with_retries(batch, events, body, headers)
        if outcome is None:  # its answers kept not adding up
            return self._halve(batch, events)
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
        self.stats.count_split()
        return [
            dead for part in split_refused(events, outcome) for dead in self._deliver(batch, part)
        ]

    def _halve(self, batch: Batch, events: Sequence[QueuedEvent]) -> list[DeadLetter]:
        self.stats.count_split()
        middle = len(events) // 2
        return self._deliver(batch, events[:middle]) + self._deliver(batch, events[middle:])

    @property
    def _encoding(self) -> str:
        return self.policy.http_compression

    def _encoder(self) -> BodyEncoder:
        encoder = getattr(self._encoders, "encoder", None)
        if encoder is None:
            encoder = self._encoders.encoder = BodyEncoder(self._encoding)
        return encoder

    def _send_with_retries(
        self, batch: Batch, events: Sequence[QueuedEvent], body: bytes, headers: dict[str, str]
    ) -> Outcome | None:
        """Send until PhyCloud's answer is final; None when UNACCOUNTED_BEFORE_SPLIT
        answers in a row did not account for ``events`` (more than one): halve them."""
        event_ids = [event.event_id for event in events]
        unaccounted = 0  # answers in a row that did not account for these events

        def wait(state: RetryCallState) -> float:
            # one event whose answers never add up: no halving left, so no hurry
            return self._backoff.seconds(state, long=unaccounted >= UNACCOUNTED_BEFORE_SPLIT)

        retrying = Retrying(
            retry=retry_if_exception_type(TransientSendError),
            wait=wait,
            sleep=self._wait_or_stop,
            before_sleep=lambda state: self._before_retry(batch, state),
            reraise=True,
        )
        for attempt in retrying:
            with attempt:
                if self.stop.is_set():
                    raise Stopped
                if self.store.stepped_since(batch.claimed_at):  # one indexed lookup
                    raise Restamped
                self._throttle.wait(len(body))
                started = time.monotonic()
                try:
                    reply = self.transport.post_events(body, headers)
                    # the wall clock: a Retry-After date is one
                    outcome = classify(reply, event_ids, time.time())
                except UnaccountedAnswerError as exc:
                    unaccounted += 1
                    if unaccounted >= UNACCOUNTED_BEFORE_SPLIT and len(events) > 1:
                        self.stats.count_retry(exc, self._clock())  # counted as the ones before
                        say_halving(exc, len(events))
                        return None
                    raise
                except TransientSendError:
                    unaccounted = 0
                    raise
                self.stats.observe_latency(time.monotonic() - started)
                self._record_success(len(events), len(body), reply.status)
                return outcome
        raise AssertionError("tenacity returns or raises")

    # ------------------------------------------------------------------ waits

    def _wait_or_stop(self, seconds: float) -> None:
        """Wait ``seconds`` (a backoff, the upload throttle, a queue in trouble) through
        ``sleep``, keeping the heartbeat; cut short by a stop or the drain's deadline,
        and then raise Stopped: the batch being retried goes back to the queue."""
        if self._deadline is not None:
            seconds = min(seconds, max(0.0, self._deadline - time.monotonic()))
        self._spend_wait(seconds)
        if self.stop.is_set() or self._past_deadline():
            raise Stopped

    def _wait_beating(self, seconds: float) -> None:
        """Wait ``seconds`` or until stopped, beating at least once a second (and once
        at the end): a waiting sender is no hung one."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0 and not self.stop.wait(min(left, BEAT_S)):
            self._beat()

    def _before_retry(self, batch: Batch, state: RetryCallState) -> None:
        exc = state.outcome.exception() if state.outcome else None
        self._lanes.failed(self.store.now())
        self.stats.count_retry(exc, self._clock())
        say_retrying(exc, state.attempt_number, state.upcoming_sleep)
        with contextlib.suppress(QueueError):  # a lease that runs out only means a resend
            self.store.renew(batch)

    def _record_success(self, events: int, size: int, status: int) -> None:
        self._lanes.succeeded()
        if 200 <= status < 300:
            self.stats.add_sent(events, size, status, self._clock())
        else:
            self.stats.set_status(status)
