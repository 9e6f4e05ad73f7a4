"""The bridge as a service: the pipeline, the queue writer, the sender, the heartbeat
and the queue's maintenance, each a supervised worker, and a clean stop.

Threads: ``ingest`` (the input's loop), ``sampler`` (the sample tick, for live
inputs), ``writer``, ``sender``, ``heartbeat`` (which also emits the ``bridge.health``
events) and ``maintenance``. They share only the queue file and the writer's
hand-off, so a stalled PhyCloud never slows ingest and a burst of messages never
blocks a send. ``runtime/wiring.py`` builds every part; this module only runs them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from phytrace_edge._version import __version__
from phytrace_edge.errors import QueueError
from phytrace_edge.host_memory import give_back_free_memory
from phytrace_edge.ingest.sources.base import Finished
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime import marks
from phytrace_edge.runtime.health import stalled
from phytrace_edge.runtime.health_events import HealthEvents
from phytrace_edge.runtime.heartbeat import HEARTBEAT_S, Heartbeat
from phytrace_edge.runtime.logs import RepeatedLine
from phytrace_edge.runtime.options import ServiceOptions
from phytrace_edge.runtime.pipeline import Pipeline
from phytrace_edge.runtime.sd_notify import status_line
from phytrace_edge.runtime.supervisor import Beat, Supervisor, Worker
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.ship.sender import Sender
from phytrace_edge.units import format_bytes

log = logging.getLogger(__name__)

MAINTENANCE_EVERY_S = 60.0
REPORT_EVERY_S = 30.0  # a queue that keeps failing: the first line, then a summary
STOP_TIMEOUT_S = 5.0
STOP_MARGIN_S = 8.0  # beyond SHUTDOWN_GRACE_S: a commit under way, a request on the wire
CLOSE_WITHIN_S = 2.0
T = TypeVar("T")


class BridgeService:
    """Start with ``start()``; stop with ``shutdown()``."""

    def __init__(
        self,
        options: ServiceOptions,
        pipeline: Pipeline,
        store: QueueStore,
        sender: Sender,
        writer: QueueWriter,
        heartbeat: Heartbeat,
        health_events: HealthEvents,
        supervisor: Supervisor,
    ) -> None:
        self.options = options
        self.pipeline = pipeline
        self.store = store
        self.sender = sender
        self.writer = writer
        self.heartbeat = heartbeat
        self.health_events = health_events
        self.supervisor = supervisor
        self.finished = threading.Event()  # a finite input (a bag) was read to its end
        self.store_depth_at_stop = 0
        self.lost_at_stop = 0  # events built and never written (unwritable)
        self._queue_trouble = RepeatedLine("queue", REPORT_EVERY_S)
        self._metrics: object | None = None
        self._on_stopped: list[Callable[[], None]] = []

    def on_stopped(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` once the service has stopped (its queue closed)."""
        self._on_stopped.append(callback)

    def summary(self) -> str:
        o = self.options
        return (
            f"phytrace-edge {__version__}: {o.source_id} ({o.source_type}) input "
            f"{o.input_label} at {o.sample_rate_hz:g} Hz -> {o.endpoint_host}; queue "
            f"{self.store.path} ({self.store.counter('depth')} events, cap "
            f"{format_bytes(self.store.limits.max_bytes)})"
        )

    def status_line(self) -> str:
        """One line for `systemctl status`."""
        return status_line(self.store.counter("depth"), self.sender.stats, self.store.now())

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Open the input and start every worker."""
        self.pipeline.open()
        start = self.supervisor.start
        start(Worker("writer", self.writer.run, self.writer.stop))
        start(Worker("sender", self.sender.run, self.sender.stop))
        start(Worker("heartbeat", self._heartbeat_loop))
        start(Worker("maintenance", self._maintenance_loop))
        if self.options.marks_dir is not None:
            start(Worker("marks", self._marks_loop))
        start(Worker("ingest", self._ingest_loop, finite=True))
        if self.pipeline.ticks_itself:
            start(Worker("sampler", self.pipeline.tick))
        try:
            self.heartbeat.write(running=True)
        except QueueError as exc:  # a full disk must not keep the bridge from starting
            log.warning("heartbeat not written: %s", exc)
        if self.options.metrics_port:
            from phytrace_edge.runtime.metrics import serve_metrics  # prometheus_client

            self._metrics = serve_metrics(
                self.heartbeat.figures, self.options.metrics_host, self.options.metrics_port
            )

    def _ingest_loop(self, stop: threading.Event, beat: Beat) -> None:
        self.pipeline.ingest(stop, beat)
        if not stop.is_set():
            self.finished.set()

    def _heartbeat_loop(self, stop: threading.Event, beat: Beat) -> None:
        while not stop.wait(HEARTBEAT_S):
            self._beat_once()
            beat()

    def _beat_once(self) -> None:
        """Look after the queue file, write the figures (the live status first, which
        needs no queue), then what needs the queue: the clocks and a health event."""
        try:
            self.store.watch_file()
        except OSError as exc:  # the descriptor itself failed: say so, go on
            self._queue_trouble.report(f"cannot look at the queue file: {exc}")
        # the live status first: it waits for nothing the disk does
        document = self.heartbeat.write_live_now(running=True)
        try:
            self.store.record_clocks()  # a step of the wall clock is seen within a beat
            self.heartbeat.write_queue_row(document)
            stats = self.store.stats()
        except QueueError as exc:  # failing, busy or full for now: the next beat tries again
            self._queue_trouble.report(f"heartbeat not written to the queue: {exc}")
            return
        self._queue_trouble.clear()
        try:
            self.health_events.emit_if_due(stats, self.store.now(), live=document)
        except QueueError as exc:
            self._queue_trouble.report(f"no health event: {exc}")

    def _marks_loop(self, stop: threading.Event, beat: Beat) -> None:
        """Take the marks ``phytrace-edge mark`` leaves (runtime/marks.py)."""
        folder = self.options.marks_dir
        assert folder is not None
        while not stop.wait(marks.POLL_S):
            beat()
            for request in marks.pending_marks(folder):
                marks.answer(request, self._take_mark(request))

    def _take_mark(self, request: marks.MarkRequest) -> dict[str, Any]:
        """A mark as an incident's trigger, at the moment it was made; its answer."""
        age_s = time.time() - request.at_wall_s
        if age_s > self.options.incident_before_s:
            return {
                "outcome": "too_old",
                "detail": f"made {age_s:.0f} s ago, before the window (INCIDENT_BEFORE_S "
                f"{self.options.incident_before_s:g} s): no bridge ran to take it then",
            }
        marked = self.pipeline.recorder.mark(request.reason, request.at_wall_s)
        log.warning("incident marked by hand (%s): %s", marked.outcome, request.reason)
        return {"outcome": marked.outcome, "incident_id": marked.incident_id}

    def _maintenance_loop(self, stop: threading.Event, beat: Beat) -> None:
        due = time.monotonic() + MAINTENANCE_EVERY_S
        while not stop.wait(HEARTBEAT_S):
            beat()
            if time.monotonic() < due:
                continue
            due = time.monotonic() + MAINTENANCE_EVERY_S
            try:
                self.store.maintain()
                give_back_free_memory()  # a drained backlog's buffers, freed but kept mapped
                log.debug("queue maintenance pass done")
            except QueueError as exc:
                self._queue_trouble.report(f"queue maintenance failed ({exc}); will try again")

    def healthy(self) -> bool:
        """Whether every worker runs and made progress lately (feeds the watchdog)."""
        if self.supervisor.failed.is_set():
            return False
        ages = self.supervisor.progress_ages().values()
        return not any(stalled(age, self.options.stall_after_s) for age in ages)

    def finished_input(self) -> Finished | None:
        """What a finite input did, once it ended or was stopped (a bag replay's
        summary); None for a live input."""
        return self.pipeline.source.finished()

    def shutdown(self, grace_s: float) -> None:
        """Stop in order: ingest, then queue what was built (and a last health event),
        then let the sender flush, then the rest: the flush within ``grace_s``, the
        whole stop within ``grace_s + STOP_MARGIN_S + 2 * CLOSE_WITHIN_S`` whatever the
        disk does (docs/operations.md, "Stopping"). What could not be written by then is
        counted (``unwritable``) and the process exits non-zero (``lost_at_stop``)."""
        flush_by = time.monotonic() + grace_s
        give_up_at = flush_by + STOP_MARGIN_S

        def left(bound: float = STOP_TIMEOUT_S) -> float:
            return max(0.0, min(bound, give_up_at - time.monotonic()))

        sup = self.supervisor
        sup.stop("sampler", left())
        sup.stop("ingest", left())
        self.pipeline.close()
        sup.stop("heartbeat", left())
        self._stop_health_event()
        writer = self.writer
        writer.request_stop(within_s=max(0.0, flush_by - time.monotonic()))
        if not sup.stop("writer", left(grace_s + STOP_TIMEOUT_S)):
            writer.abandon()  # a commit still under way on a disk that hangs
        self._flush_sender(flush_by)
        for name in ("sender", "maintenance"):
            sup.stop(name, left())
        if self._metrics is not None:
            self._metrics.shutdown()  # type: ignore[attr-defined]
        self.sender.transport.close()
        self.lost_at_stop = writer.dropped["unwritable"]
        # the final figures: into the queue, and into the live status, which stays (it
        # keeps counts the queue could not take, and tells the next start of this boot
        # that a queue was here)
        run_within(self._record_stop, max(left(), CLOSE_WITHIN_S), "recording the stop")
        run_within(self.store.close, CLOSE_WITHIN_S, "closing the queue")
        for callback in self._on_stopped:
            callback()

    def _stop_health_event(self) -> None:
        """A last ``bridge.health`` event, from the last heartbeat's figures: the stop
        does not wait for a slow disk to read them again."""
        stats, document = self.heartbeat.last_stats, self.heartbeat.last_document
        if stats is None or document is None:
            return
        try:
            self.health_events.emit_if_due(stats, self.store.now(), trigger="stop", live=document)
        except QueueError as exc:
            log.warning("no stop health event: %s", exc)

    def _record_stop(self) -> bool:
        """The final figures, into the live status and the queue; False when the queue
        could not take them (the live status then holds the truth)."""
        writer = self.writer
        try:
            self.heartbeat.write(running=False)
            left = self.store_depth_at_stop = self.store.counter("depth")
        except QueueError as exc:
            self.heartbeat.write_live(self.heartbeat.document(running=False))
            log.error(
                "could not record the stop in the queue (%s); the counts are in the live status %s",
                exc,
                self.heartbeat.live_path,
            )
            return False
        log.info("stopped; %d event(s) left in the queue for next time", left)
        if self.lost_at_stop:
            log.error(
                "%d event(s) built in this run could not be written to the queue "
                "before the stop (counted as dropped: unwritable) - check the disk",
                writer.dropped["unwritable"],
            )
        return True

    def _flush_sender(self, deadline: float) -> None:
        """Let the sender send partial batches at once until the queue is empty or
        the ``deadline`` (monotonic) has come."""
        self.sender.flushing.set()
        sender = self.supervisor.workers["sender"]
        while time.monotonic() < deadline and self._depth_or_zero() > 0:
            if sender.done.wait(0.05):
                break

    def _depth_or_zero(self) -> int:
        try:
            return self.store.counter("depth")
        except QueueError:
            return 0


def run_within(work: Callable[[], T], timeout_s: float, what: str) -> T | None:
    """``work()``'s result, or None when it did not finish within ``timeout_s``. For
    the last steps of a stop on a disk that hangs: a commit or a checkpoint can take
    seconds per fsync. Whatever was committed is durable in the WAL already, so a
    process that ends during them loses nothing that was counted as queued."""
    result: list[T] = []
    worker = threading.Thread(target=lambda: result.append(work()), name=what, daemon=True)
    worker.start()
    worker.join(timeout_s)
    if worker.is_alive():
        log.warning("%s takes over %.0f s (a slow disk); exiting without it", what, timeout_s)
    return result[0] if result else None
