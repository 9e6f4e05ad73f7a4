"""The bridge as a service: source -> writer -> queue -> sender, and a clean stop.

Threads: the source's executor (ingest and build), the queue writer, the sender and
the maintenance loop. They share only the queue file and the writer's hand-off, so a
stalled PhyCloud never slows ingest and a burst of messages never blocks a send.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from phytrace_edge import __version__
from phytrace_edge.config import Settings, format_bytes
from phytrace_edge.queue import QueueLimits, QueueStore
from phytrace_edge.runtime.sources import Source, make_source
from phytrace_edge.runtime.state import HEARTBEAT_S, Rates, service_document, write_state
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.ship import HttpTransport, Sender, SendPolicy, Transport
from phytrace_edge.udm.schema import check_event

log = logging.getLogger(__name__)

MAINTENANCE_EVERY_S = 60.0


def open_queue(settings: Settings) -> QueueStore:
    """The queue named by the settings. The lease outlives the longest retry wait, so a
    batch that is still being retried is not taken by a second sender."""
    return QueueStore.open(
        str(settings.queue_path),
        limits=QueueLimits(
            max_bytes=settings.queue_max_bytes,
            max_events=settings.queue_max_events,
            on_full=settings.queue_on_full,
            ttl_s=settings.queue_ttl_s,
        ),
        compression=settings.queue_compression,
        sync=settings.queue_sync,
        lease_s=max(60.0, 2 * (settings.retry_max_s + settings.http_timeout_s)),
    )


def send_policy(settings: Settings) -> SendPolicy:
    return SendPolicy(
        batch_size=settings.batch_size,
        batch_max_bytes=settings.batch_max_bytes,
        flush_interval_s=settings.flush_interval_s,
        retry_min_s=settings.retry_min_s,
        retry_max_s=settings.retry_max_s,
        http_compression=settings.http_compression,
        upload_max_bps=settings.upload_max_bps,
    )


def http_transport(settings: Settings) -> HttpTransport:
    return HttpTransport(
        settings.phycloud_endpoint,
        settings.phycloud_api_key,
        settings.http_timeout_s,
        settings.ca_bundle,
    )


def warn_if_not_on_a_volume(queue_path: Path, env: Mapping[str, str]) -> bool:
    """In the container, a queue that is not on a mounted volume dies with the container
    and takes the backlog with it: say so loudly. True when it warned."""
    if not env.get("PHYTRACE_CONTAINER"):
        return False
    folder = queue_path.resolve().parent
    if any(os.path.ismount(p) for p in (folder, *folder.parents) if str(p) != "/"):
        return False
    log.warning(
        "!!! the queue %s is not on a mounted volume: the backlog will be lost with the "
        "container. Mount a volume at %s (docker run -v phytrace-queue:%s, or compose's "
        "volumes) !!!",
        queue_path,
        folder,
        folder,
    )
    return True


class BridgeService:
    """Start with ``start()``; stop with ``shutdown()``."""

    def __init__(
        self,
        settings: Settings,
        transport: Transport | None = None,
        on_event: Callable[[dict[str, Any]], None] | None = None,
        ros_args: list[str] | None = None,
    ) -> None:
        warn_if_not_on_a_volume(Path(str(settings.queue_path)), os.environ)
        self.settings = settings
        self._on_event = on_event
        self.events_built = 0
        self.store = open_queue(settings)
        self.writer = QueueWriter(self.store)
        self.sender = Sender(
            self.store, transport or http_transport(settings), send_policy(settings)
        )
        self.source: Source = make_source(settings, self._emit, ros_args or [])
        self._stop_maintenance = threading.Event()
        self._rates = Rates()
        self._metrics: Any = None
        self.store_depth_at_stop = 0
        self.started_at = time.time()
        self._threads = [
            threading.Thread(target=self.sender.run, name="sender", daemon=True),
            threading.Thread(target=self._maintain, name="maintenance", daemon=True),
        ]

    def _emit(self, event: dict[str, Any]) -> None:
        self.events_built += 1
        check_event(event, log)  # a violation is logged; the event is still kept
        if self._on_event is not None:
            self._on_event(event)
        self.writer.put(event)

    def summary(self) -> str:
        s = self.settings
        depth = self.store.stats_counter("depth")
        return (
            f"phytrace-edge {__version__}: {s.source_id} ({s.source_type}) input {s.bridge_input} "
            f"at {s.sample_rate_hz:g} Hz -> {urlsplit(s.phycloud_endpoint).netloc}; queue "
            f"{s.queue_path} ({depth} events, cap {format_bytes(s.queue_max_bytes)})"
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
            f"{self.store.stats_counter('depth')} queued, {stats.events_sent} sent, "
            f"last success {last}"
            + (f", last error {stats.last_error}" if stats.last_error else "")
        )

    def alive(self) -> bool:
        """Whether the sender, maintenance and writer threads all still run."""
        return all(thread.is_alive() for thread in self._threads) and self.writer.alive()

    def start(self) -> None:
        self.writer.start()
        for thread in self._threads:
            thread.start()
        self.source.start()
        self.heartbeat(running=True)
        if self.settings.metrics_port:
            from phytrace_edge.runtime.metrics import serve_metrics

            self._metrics = serve_metrics(
                self, self.settings.metrics_host, self.settings.metrics_port
            )

    def _maintain(self) -> None:
        """Heartbeat every HEARTBEAT_S; queue upkeep (TTL, space) every minute."""
        last_upkeep = time.monotonic()
        while not self._stop_maintenance.wait(HEARTBEAT_S):
            try:
                self.heartbeat(running=True)
                if time.monotonic() - last_upkeep >= MAINTENANCE_EVERY_S:
                    last_upkeep = time.monotonic()
                    self.store.maintain()
            except Exception:
                log.exception("queue maintenance failed; will try again")

    def heartbeat(self, running: bool) -> None:
        """Write the figures `status` shows (another process reads them)."""
        dispatcher, builder = self.source.bridge.dispatcher, self.source.bridge.builder
        now = time.time()
        rates = self._rates.update(
            {
                "send": self.sender.stats.events_sent,
                **{f"topic:{t}": n for t, n in dispatcher.received.items()},
            },
            now,
        )
        ages = builder.topic_ages()
        topics = {
            topic: {
                "received": received,
                "rate_hz": rates.get(f"topic:{topic}", 0.0),
                "last_seen_age_s": ages.get(topic),
                "rejected": {
                    reason: n for (t, reason), n in dispatcher.rejected.items() if t == topic
                },
            }
            for topic, received in sorted(dispatcher.received.items())
        }
        sender = {**self.sender.stats.as_dict(), "send_rate_eps": rates.get("send", 0.0)}
        s = self.settings
        document = service_document(
            {
                "input": s.bridge_input,
                "source_id": s.source_id,
                "endpoint_host": urlsplit(s.phycloud_endpoint).netloc,
            },
            sender,
            topics,
            {"events_built": self.events_built, "writer_dropped": self.writer.events_dropped},
            self.started_at,
        )
        write_state(self.store, document, running)

    def shutdown(self, grace_s: float) -> None:
        """Stop ingest, queue what was built, let the sender flush for up to ``grace_s``."""
        self.source.stop()
        self.writer.stop()
        self.sender.flushing.set()
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and self.store.stats_counter("depth") > 0:
            if self.sender.stop.wait(0.05):
                break
        self.sender.stop.set()
        self._stop_maintenance.set()
        if self._metrics is not None:
            self._metrics.shutdown()
        for thread in self._threads:
            thread.join(timeout=5)
        self.sender.transport.close()
        self.heartbeat(running=False)
        left = self.store_depth_at_stop = self.store.stats_counter("depth")
        self.store.close()
        log.info("stopped; %d event(s) left in the queue for next time", left)
