"""Prometheus metrics (METRICS_PORT, off by default): a collector that reads the live
figures of the service at each scrape, so nothing is counted twice or goes stale."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

from prometheus_client import start_http_server
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import CollectorRegistry

from phytrace_edge.runtime.heartbeat import Figures
from phytrace_edge.ship.stats import LATENCY_BUCKETS_S

log = logging.getLogger(__name__)


class BridgeCollector:
    def __init__(self, read_figures: Callable[[], Figures]) -> None:
        self._read_figures = read_figures

    def collect(self) -> Iterator[Metric]:
        figures = self._read_figures()
        stats, sender, now = figures.queue, figures.sender, figures.now

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
        yield gauge(
            "backlog_oldest_age_seconds",
            "Age of the oldest event the backfill lane has yet to send.",
            None if stats.oldest_queued_at is None else now - stats.oldest_queued_at,
        )
        yield gauge(
            "live_lag_seconds",
            "How old the newest event PhyCloud accepted was, now.",
            None if sender.newest_delivered_at is None else now - sender.newest_delivered_at,
        )
        by_lane = CounterMetricFamily(
            "phytrace_events_sent_by_lane", "Events PhyCloud accepted, by lane.", labels=["lane"]
        )
        by_lane.add_metric(["live"], sender.live_events_sent)
        by_lane.add_metric(["backfill"], sender.backfill_events_sent)
        yield by_lane
        yield gauge("dead_letters", "Events kept as dead letters.", stats.dead_letters)
        yield counter("events_built", "UDM events built.", figures.events_built)
        yield counter("events_queued", "Events put into the queue (ever).", stats.queued_total)
        yield counter("events_sent", "Events PhyCloud accepted (ever).", stats.acked_total)
        dropped = CounterMetricFamily(
            "phytrace_events_dropped", "Events dropped, by reason.", labels=["reason"]
        )
        for reason, count in stats.drops.items():
            dropped.add_metric([reason], count)
        yield dropped
        if (writer := figures.writer) is not None:
            yield gauge(
                "writer_backlog_events",
                "Events built and waiting in memory for the queue's disk.",
                writer["backlog"],
            )
            yield gauge(
                "queue_commit_seconds",
                "How long the last group commit to the queue took.",
                writer["commit_s"],
            )
            yield gauge(
                "queue_commit_max_seconds",
                "The slowest group commit to the queue in the last minute.",
                writer["commit_max_s"],
            )
            yield gauge(
                "queue_writes_failing_seconds",
                "How long queue writes have failed (0 while they work).",
                writer["writes_failing_s"] or 0.0,
            )
        restarts = CounterMetricFamily(
            "phytrace_thread_restarts", "Threads restarted after a failure.", labels=["thread"]
        )
        for thread, count in figures.thread_restarts.items():
            restarts.add_metric([thread], count)
        yield restarts
        yield counter("send_retries", "Send attempts retried.", sender.retries)
        yield counter(
            "batches_split", "Batches split to isolate rejected events.", sender.batches_split
        )
        yield counter("auth_failures", "Answers 401/403.", sender.auth_failures)
        yield counter(
            "unexpected_answers",
            "Answers on which nothing was deleted: not PhyCloud's, or not adding up.",
            sender.unexpected_answers,
        )
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
        yield from _topics(figures.topics)


def _topics(topics: dict[str, dict[str, Any]]) -> Iterator[Metric]:
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
    for topic, figures in topics.items():
        received.add_metric([topic], figures["received"])
        if figures.get("last_seen_age_s") is not None:
            ages.add_metric([topic], figures["last_seen_age_s"])
        for reason, count in figures.get("rejected", {}).items():
            rejected.add_metric([topic, reason], count)
        if "qos_incompatible" in figures:
            incompatible.add_metric([topic], figures["qos_incompatible"])
    yield from (received, ages, rejected, incompatible)


def serve_metrics(read_figures: Callable[[], Figures], host: str, port: int) -> Any:
    """Serve /metrics on host:port in a daemon thread; the server object."""
    registry = CollectorRegistry()
    registry.register(BridgeCollector(read_figures))
    server, _thread = start_http_server(port, addr=host, registry=registry)
    log.info("metrics on http://%s:%d/metrics", host, server.server_port)
    return server
