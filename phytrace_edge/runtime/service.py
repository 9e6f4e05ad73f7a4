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

from phytrace_edge._version import __version__
from phytrace_edge.errors import QueueError
from phytrace_edge.host_memory import give_back_free_memory
from phytrace_edge.ingest.sources.base import Finished
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime.health import stalled
from phytrace_edge.runtime.health_events import HealthEvents
from phytrace_edge.runtime.heartbeat import HEARTBEAT_S, Heartbeat
from phytrace_edge.runtime.options import ServiceOptions
from phytrace_edge.runtime.outlet import Outlet
from phytrace_edge.runtime.pipeline import Pipeline
from phytrace_edge.runtime.sd_notify import status_line
from phytrace_edge.runtime.supervisor import Beat, Supervisor, Worker
from phytrace_edge.ship.sender import Sender
from phytrace_edge.units import format_bytes

log = logging.getLogger(__name__)

MAINTENANCE_EVERY_S = 60.0
STOP_TIMEOUT_S = 5.0


class BridgeService:
    """Start with ``start()``; stop with ``shutdown()``."""

    def __init__(
        self,
        options: ServiceOptions,
        pipeline: Pipeline,
        store: QueueStore,
        sender: Sender,
        outlet: Outlet,
        heartbeat: Heartbeat,
        health_events: HealthEvents,
        supervisor: Supervisor,
    ) -> None:
        self.options = options
        self.pipeline = pipeline
        self.store = store
        self.sender = sender
        self.outlet = outlet
        self.heartbeat = heartbeat
        self.health_events = health_events
        self.supervisor = supervisor
        self.finished = threading.Event()  # a finite input (a bag) was read to its end
        self.store_depth_at_stop = 0
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
        start(Worker("writer", self.outlet.writer.run, self.outlet.writer.stop))
        start(Worker("sender", self.sender.run, self.sender.stop))
        start(Worker("heartbeat", self._heartbeat_loop))
        start(Worker("maintenance", self._maintenance_loop))
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
            try:
                self.store.record_clocks()  # a step of the wall clock is seen within a beat
                self.heartbeat.write(running=True)
                self.health_events.emit_if_due(self.store.stats(), self.store.now())
            except QueueError as exc:  # busy or full for now: the next beat tries again
                log.warning("heartbeat not written: %s", exc)
            beat()

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
                log.warning("queue maintenance failed (%s); will try again", exc)

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
        then let the sender flush for up to ``grace_s``, then the rest."""
        sup = self.supervisor
        sup.stop("sampler", STOP_TIMEOUT_S)
        sup.stop("ingest", STOP_TIMEOUT_S)
        self.pipeline.close()
        sup.stop("heartbeat", STOP_TIMEOUT_S)  # it emits health events: none after the writer
        try:
            self.health_events.emit_if_due(self.store.stats(), self.store.now(), trigger="stop")
        except QueueError as exc:
            log.warning("no stop health event: %s", exc)
        self.outlet.writer.request_stop()
        sup.stop("writer", 2 * STOP_TIMEOUT_S)
        self._flush_sender(grace_s)
        for name in ("sender", "maintenance"):
            sup.stop(name, STOP_TIMEOUT_S)
        if self._metrics is not None:
            self._metrics.shutdown()  # type: ignore[attr-defined]
        self.sender.transport.close()
        try:  # the final figures: events_built and the counters agree at a clean stop
            self.heartbeat.write(running=False)
            left = self.store_depth_at_stop = self.store.counter("depth")
        except QueueError as exc:
            log.error("could not record the stop in the queue: %s", exc)
            left = -1
        self.store.close()
        for callback in self._on_stopped:
            callback()
        if left >= 0:
            log.info("stopped; %d event(s) left in the queue for next time", left)

    def _flush_sender(self, grace_s: float) -> None:
        """Let the sender send partial batches at once until the queue is empty or
        ``grace_s`` is over."""
        self.sender.flushing.set()
        deadline = time.monotonic() + grace_s
        sender = self.supervisor.workers["sender"]
        while time.monotonic() < deadline and self.store.counter("depth") > 0:
            if sender.done.wait(0.05):
                break
