"""Prometheus metrics (METRICS_PORT, off by default): a collector that reads the live
state of the service at each scrape, so nothing is counted twice or goes stale."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from prometheus_client import start_http_server
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import CollectorRegistry

from phytrace_edge.ship.sender import LATENCY_BUCKETS_S

if TYPE_CHECKING:
    from phytrace_edge.runtime.service import BridgeService

log = logging.getLogger(__name__)


class BridgeCollector:
    def __init__(self, service: BridgeService) -> None:
        self.service = service

    def collect(self) -> Iterator[Metric]:
        service = self.service
        stats = service.store.stats()
        sender = service.sender.stats
        now = service.store.now()

        def gauge(name: str, doc: str, value: float | None) -> GaugeMetricFamily:
            return GaugeMetricFamily(f"phytrace_{name}", doc, value=value if value else 0.0)

        def counter(name: str, doc: str, value: float) -> CounterMetricFamily:
            return CounterMetricFamily(f"phytrace_{name}", doc, value=value)

        yield gauge("queue_depth", "Events waiting in the queue.", stats.depth)
        yield gauge("queue_bytes", "Bytes of the queue's files on disk.", stats.file_bytes)
        yield gauge("queue_max_bytes", "QUEUE_MAX_BYTES.", stats.max_bytes)
        yield gauge(
            "queue_oldest_age_seconds",
            "Age of the oldest queued event.",
            None if stats.oldest_queued_at is None else now - stats.oldest_queued_at,
        )
        yield gauge("dead_letters", "Events kept as dead letters.", stats.dead_letters)
        yield counter("events_built", "UDM events built.", service.events_built)
        yield counter("events_queued", "Events put into the queue (ever).", stats.queued_total)
        yield counter("events_sent", "Events PhyCloud accepted (ever).", stats.acked_total)
        dropped = CounterMetricFamily(
            "phytrace_events_dropped", "Events dropped, by reason.", labels=["reason"]
        )
        for reason, count in stats.drops.items():
            dropped.add_metric([reason], count)
        dropped.add_metric(["writer_backlog"], service.writer.events_dropped)
        yield dropped
        yield counter("send_retries", "Send attempts retried.", sender.retries)
        yield counter(
            "batches_split", "Batches split to isolate rejected events.", sender.batches_split
        )
        yield counter("auth_failures", "Answers 401/403.", sender.auth_failures)
        yield gauge(
            "last_success_timestamp_seconds",
            "When PhyCloud last accepted a batch.",
            sender.last_success_at,
        )
        buckets = [
            (str(bound), count)
            for bound, count in zip(LATENCY_BUCKETS_S, sender.latency_buckets, strict=True)
        ]
        buckets.append(("+Inf", sender.latency_count))
        yield HistogramMetricFamily(
            "phytrace_send_latency_seconds",
            "Duration of one request.",
            buckets=buckets,
            sum_value=sender.latency_sum_s,
        )
        yield from self._topics()

    def _topics(self) -> Iterator[Metric]:
        bridge = self.service.source.bridge
        received = CounterMetricFamily(
            "phytrace_topic_messages", "Messages received.", labels=["topic"]
        )
        ages = GaugeMetricFamily(
            "phytrace_topic_last_seen_age_seconds",
            "Seconds since the topic's latest message.",
            labels=["topic"],
        )
        rejected = CounterMetricFamily(
            "phytrace_topic_rejected", "Messages rejected.", labels=["topic", "reason"]
        )
        incompatible = CounterMetricFamily(
            "phytrace_topic_qos_incompatible",
            "Publishers whose QoS the subscription could not match.",
            labels=["topic"],
        )
        for topic, count in bridge.dispatcher.received.items():
            received.add_metric([topic], count)
        for topic, age in bridge.builder.topic_ages().items():
            ages.add_metric([topic], age)
        for (topic, reason), count in bridge.dispatcher.rejected.items():
            rejected.add_metric([topic, reason], count)
        for topic, count in getattr(bridge, "qos_incompatible", {}).items():
            incompatible.add_metric([topic], count)
        yield from (received, ages, rejected, incompatible)


def serve_metrics(service: BridgeService, host: str, port: int) -> Any:
    """Serve /metrics on host:port in a daemon thread; the server object."""
    registry = CollectorRegistry()
    registry.register(BridgeCollector(service))
    server, _thread = start_http_server(port, addr=host, registry=registry)
    log.info("metrics on http://%s:%d/metrics", host, server.server_port)
    return server
