"""The bridge as a service: source -> sampler -> writer -> queue -> sender, supervised,
and a clean stop.

Threads (each a supervised worker): ``ingest`` (the source's loop), ``sampler`` (the
sample tick, for live inputs), ``writer``, ``sender``, ``heartbeat`` (which also
emits the ``bridge.health`` events) and ``maintenance``. They share only the queue
file and the writer's hand-off, so a stalled PhyCloud never slows ingest and a burst
of messages never blocks a send.
``runtime/wiring.py`` builds the parts; this module runs them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from phytrace_edge._version import __version__
from phytrace_edge.builder.builder import Built, UDMBuilder
from phytrace_edge.builder.sampler import Sampler
from phytrace_edge.errors import QueueError
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.sources.base import Feed, Finished, Source
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime.health import Thresholds, report, stalled
from phytrace_edge.runtime.health_events import HealthSchedule, health_event
from phytrace_edge.runtime.heartbeat import (
    HEARTBEAT_S,
    Figures,
    Rates,
    service_document,
    topic_report,
)
from phytrace_edge.runtime.supervisor import Beat, Supervisor, Worker
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.ship.sender import Sender
from phytrace_edge.udm.schema import check_event
from phytrace_edge.units import format_bytes

log = logging.getLogger(__name__)

MAINTENANCE_EVERY_S = 60.0
STOP_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class ServiceOptions:
    """What the service itself needs to know (the rest is in its parts)."""

    input_label: str  # BRIDGE_INPUT as configured
    source_id: str
    source_type: str
    endpoint_host: str
    sample_rate_hz: float
    shutdown_grace_s: float
    stall_after_s: float = 30.0  # a worker without progress this long is stuck
    metrics_host: str = "127.0.0.1"
    metrics_port: int = 0
    health_event_interval_s: float = 0.0  # 0: no bridge.health events
    thresholds: Thresholds | None = None  # what the health events judge by


class BridgeService:
    """Start with ``start()``; stop with ``shutdown()``."""

    def __init__(
        self,
        options: ServiceOptions,
        store: QueueStore,
        sender: Sender,
        source: Source,
        builder: UDMBuilder,
        on_event: Callable[[dict[str, Any]], None] | None = None,
        supervisor: Supervisor | None = None,
    ) -> None:
        self.options = options
        self.store = store
        self.sender = sender
        self.source = source
        self.builder = builder
        self.dispatcher = Dispatcher(builder.add_reading, builder.add_message)
        self.writer = QueueWriter(store)
        self.sampler = Sampler(
            builder, self._emit, options.sample_rate_hz, before_tick=source.before_tick
        )
        self.supervisor = supervisor or Supervisor()
        self.finished = threading.Event()  # a finite input (a bag) was read to its end
        self.events_built = 0
        self._emit_lock = threading.Lock()  # the sampler and the heartbeat both emit
        self._health = HealthSchedule(options.health_event_interval_s)
        self.store_depth_at_stop = 0
        self.started_at = time.time()
        self._on_event = on_event
        self._rates = Rates()
        self._metrics: Any = None
        self._on_stopped: list[Callable[[], None]] = []

    def on_stopped(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` once the service has stopped (its queue closed)."""
        self._on_stopped.append(callback)

    def _emit(self, built: Built) -> None:
        with self._emit_lock:
            self.events_built += 1
        check_event(built.event, log)  # a violation is logged; the event is still kept
        if self._on_event is not None:
            self._on_event(built.event)
        self.writer.put(built, wait=self.source.keeps_time)  # a bag waits for the disk

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
        stats = self.sender.stats
        last = (
            "never"
            if stats.last_success_at is None
            else (f"{time.time() - stats.last_success_at:.0f} s ago")
        )
        return (
            f"{self.store.counter('depth')} queued, {stats.events_sent} sent, "
            f"last success {last}"
            + (f", last error {stats.last_error}" if stats.last_error else "")
        )

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Open the input and start every worker."""
        self.source.start(
            Feed(self.dispatcher.on_message, self.sampler.tick, self.sampler.period_s)
        )
        start = self.supervisor.start
        start(Worker("writer", self.writer.run, self.writer.stop))
        start(Worker("sender", self.sender.run, self.sender.stop))
        start(Worker("heartbeat", self._heartbeat_loop))
        start(Worker("maintenance", self._maintenance_loop))
        ingest = Worker("ingest", self._ingest_loop, finite=True)
        start(ingest)
        if not self.source.keeps_time:
            start(Worker("sampler", lambda beat: self.sampler.run(ingest.stop, beat), ingest.stop))
        try:
            self.heartbeat(running=True)
        except QueueError as exc:  # a full disk must not keep the bridge from starting
            log.warning("heartbeat not written: %s", exc)
        if self.options.metrics_port:
            from phytrace_edge.runtime.metrics import serve_metrics

            self._metrics = serve_metrics(
                self.figures, self.options.metrics_host, self.options.metrics_port
            )

    def _ingest_loop(self, beat: Beat) -> None:
        stop = self.supervisor.workers["ingest"].stop
        self.source.run(stop, beat)
        if not stop.is_set():
            self.finished.set()

    def _heartbeat_loop(self, beat: Beat) -> None:
        stop = self.supervisor.workers["heartbeat"].stop
        while not stop.wait(HEARTBEAT_S):
            try:
                self.heartbeat(running=True)
                self.emit_health_event()
            except QueueError as exc:  # busy or full for now: the next beat tries again
                log.warning("heartbeat not written: %s", exc)
            beat()

    def emit_health_event(self, trigger: str | None = None) -> None:
        """A ``bridge.health`` event when one is due (or ``trigger`` forces one)."""
        thresholds = self.options.thresholds
        if thresholds is None or not self.options.health_event_interval_s:
            return
        now = time.time()
        document = report(self.store.stats(), thresholds, now)
        trigger = self._health.trigger(document["healthy"], now) if trigger is None else trigger
        if trigger is not None:
            identity = self.builder.identity
            event = health_event(identity, document, trigger, now - self.started_at, now)
            self._emit(Built(event, important=trigger != "interval"))

    def _maintenance_loop(self, beat: Beat) -> None:
        stop = self.supervisor.workers["maintenance"].stop
        due = time.monotonic() + MAINTENANCE_EVERY_S
        while not stop.wait(HEARTBEAT_S):
            beat()
            if time.monotonic() < due:
                continue
            due = time.monotonic() + MAINTENANCE_EVERY_S
            try:
                self.store.maintain()
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
        return self.source.finished()

    # ------------------------------------------------------------------ figures

    def topics(self, rates: dict[str, float]) -> dict[str, dict[str, Any]]:
        known = self.source.topic_stats()
        for topic, counts in self.builder.side_counts().items():
            known[topic] = {**known.get(topic, {}), **counts}
        return topic_report(
            self.dispatcher.received,
            self.dispatcher.rejected,
            self.builder.topic_ages(),
            known,
            rates,
        )

    def stages(self) -> dict[str, dict[str, Any]]:
        sup = self.supervisor
        ages = sup.progress_ages()
        return {
            name: {
                "restarts": sup.restarts.get(name, 0),
                "progress_age_s": ages.get(name),
                "stall_after_s": self.options.stall_after_s,
                **({"failed": sup.failure} if name == sup.failed_worker else {}),
            }
            for name in sup.workers
        }

    def figures(self) -> Figures:
        """The live figures the metrics endpoint shows."""
        return Figures(
            queue=self.store.stats(),
            sender=self.sender.stats,
            events_built=self.events_built,
            writer_dropped=self.writer.events_dropped,
            topics=self.topics(self._rates.rates),
            thread_restarts=dict(self.supervisor.restarts),
            now=self.store.now(),
        )

    def heartbeat(self, running: bool) -> None:
        """Write the figures `status` shows (another process reads them)."""
        rates = self._rates.update(
            {
                "send": self.sender.stats.events_sent,
                **{f"topic:{t}": n for t, n in self.dispatcher.received.items()},
            },
            time.time(),
        )
        o = self.options
        document = service_document(
            {"input": o.input_label, "source_id": o.source_id, "endpoint_host": o.endpoint_host},
            {**self.sender.stats.as_dict(), "send_rate_eps": rates.get("send", 0.0)},
            self.topics(rates),
            self.stages(),
            {"events_built": self.events_built, "writer_dropped": self.writer.events_dropped},
            self.started_at,
        )
        self.store.write_service_state(document, running)

    def shutdown(self, grace_s: float) -> None:
        """Stop in order: ingest, then queue what was built (and a last health event),
        then let the sender flush for up to ``grace_s``, then the rest."""
        sup = self.supervisor
        sup.stop("sampler", STOP_TIMEOUT_S)
        sup.stop("ingest", STOP_TIMEOUT_S)
        self.source.stop()
        self.sampler.flush_side_events()
        sup.stop("heartbeat", STOP_TIMEOUT_S)  # it emits health events: none after the writer
        try:
            self.emit_health_event("stop")
        except QueueError as exc:
            log.warning("no stop health event: %s", exc)
        self.writer.request_stop()
        sup.stop("writer", 2 * STOP_TIMEOUT_S)
        self.sender.flushing.set()
        deadline = time.monotonic() + grace_s
        sender = sup.workers["sender"]
        while time.monotonic() < deadline and self.store.counter("depth") > 0:
            if sender.done.wait(0.05):
                break
        for name in ("sender", "maintenance"):
            sup.stop(name, STOP_TIMEOUT_S)
        if self._metrics is not None:
            self._metrics.shutdown()
        self.sender.transport.close()
        try:  # the final figures: events_built and the counters agree at a clean stop
            self.heartbeat(running=False)
            left = self.store_depth_at_stop = self.store.counter("depth")
        except QueueError as exc:
            log.error("could not record the stop in the queue: %s", exc)
            left = -1
        self.store.close()
        for callback in self._on_stopped:
            callback()
        if left >= 0:
            log.info("stopped; %d event(s) left in the queue for next time", left)
