"""The running service's figures, as ``status`` (another process) and the metrics see
them: per-second rates, per-topic figures and the document the heartbeat writes into
the queue every ``HEARTBEAT_S`` (``Heartbeat``)."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple, cast

from phytrace_edge._version import __version__
from phytrace_edge.errors import QueueError
from phytrace_edge.incident.figures import IncidentFigures
from phytrace_edge.queue.peek import QueueStats
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime import live_status
from phytrace_edge.runtime.options import ServiceOptions
from phytrace_edge.runtime.pipeline import Pipeline
from phytrace_edge.runtime.status_documents import (
    LedgerFigures,
    LinkFigures,
    QueueFileFigures,
    SenderFigures,
    ServiceDocument,
    StageFigures,
    WriterFigures,
)
from phytrace_edge.runtime.supervisor import Supervisor
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.stats import SendStats

log = logging.getLogger(__name__)

HEARTBEAT_S = 2.0
SNAPSHOT_WAIT_S = 0.5  # the live status never waits long for the queue
RATE_SMOOTHING = 0.3  # weight of the newest interval in the rate averages


@dataclass(frozen=True)
class Figures:
    """Everything the metrics endpoint shows, read at one moment."""

    queue: QueueStats
    sender: SendStats
    events_built: int
    topics: dict[str, dict[str, Any]]
    thread_restarts: dict[str, int]
    now: float
    writer: WriterFigures | None = None


@dataclass
class Rates:
    """Per-second rates from counters sampled at each heartbeat (exponential average)."""

    previous: dict[str, float] = field(default_factory=dict)
    at: float | None = None
    rates: dict[str, float] = field(default_factory=dict)

    def update(self, counters: Mapping[str, float], now: float) -> dict[str, float]:
        if self.at is not None and now > self.at:
            for name, value in counters.items():
                # a counter not there at the previous sample was 0 then: the messages
                # of a topic first heard since then count (a burst of /rosout records
                # between two heartbeats showed 0.0 Hz for ever)
                instant = max(0.0, value - self.previous.get(name, 0)) / (now - self.at)
                old = self.rates.get(name, instant)
                self.rates[name] = old + RATE_SMOOTHING * (instant - old)
        self.previous, self.at = dict(counters), now
        return {name: round(rate, 3) for name, rate in self.rates.items()}


def topic_report(
    received: Mapping[str, int],
    rejected: Mapping[tuple[str, str], int],
    ages: Mapping[str, float],
    source_stats: Mapping[str, Mapping[str, Any]],
    rates: Mapping[str, float],
) -> dict[str, dict[str, Any]]:
    """Per topic: messages received and their rate, the age of the latest, rejects by
    reason, and what the source knows (publishers, QoS problems). Every topic the
    source subscribes to appears, also one that never delivered a message."""
    topics = sorted(set(received) | set(source_stats))
    return {
        topic: {
            "received": received.get(topic, 0),
            "rate_hz": rates.get(f"topic:{topic}", 0.0),
            "last_seen_age_s": ages.get(topic),
            "rejected": {reason: n for (t, reason), n in rejected.items() if t == topic},
            **source_stats.get(topic, {}),
        }
        for topic in topics
    }


class Moment(NamedTuple):
    """The queue and its disk at one heartbeat: this run's ledger and the queue's
    counters read at the same moment, the writer's figures, the queue file's state."""

    ledger: LedgerFigures
    writer: WriterFigures
    queue_file: QueueFileFigures
    queue_counters: dict[str, int]  # counts not yet written included
    unwritten_counts: dict[str, int]  # of those, the ones only in memory
    heartbeat_at: float  # queue time
    running: bool
    boottime: float = 0.0


def service_document(
    options: ServiceOptions,
    sender: SenderFigures,
    topics: dict[str, dict[str, Any]],
    stages: dict[str, StageFigures],
    events_built: int,
    started_at: float,
    moment: Moment,
    incidents: IncidentFigures,
) -> ServiceDocument:
    """What the heartbeat row and the live status file hold (``status`` reads them)."""
    return {
        **moment._asdict(),  # type: ignore[typeddict-item]
        "pid": os.getpid(),
        "version": __version__,
        "started_at": started_at,
        "input": options.input_label,
        "source_id": options.source_id,
        "endpoint_host": options.endpoint_host,
        "sender": sender,
        "link": cast(LinkFigures, dict(options.link)),
        "topics": topics,
        "stages": stages,
        "events_built": events_built,
        "incidents": incidents,
    }


class Heartbeat:
    """Reads the figures of the running parts; ``write`` puts them into the live status
    file and the queue file for ``status``, ``figures`` hands them to the metrics
    endpoint."""

    def __init__(
        self,
        options: ServiceOptions,
        pipeline: Pipeline,
        store: QueueStore,
        sender: Sender,
        writer: QueueWriter,
        supervisor: Supervisor,
        started_at: float,
        live_path: str | None = None,
    ) -> None:
        self.options, self.pipeline, self.store = options, pipeline, store
        self.sender, self.writer, self.supervisor = sender, writer, supervisor
        self.started_at = started_at
        self.live_path = live_path
        self._rates = Rates()
        self._live_failed = False
        self.last_stats: QueueStats | None = None
        self._last_ledger: LedgerFigures | None = None  # read with last_stats
        self.last_document: ServiceDocument | None = None

    def topics(self, rates: Mapping[str, float]) -> dict[str, dict[str, Any]]:
        known = self.pipeline.source.topic_stats()
        for topic, counts in self.pipeline.builder.side_counts().items():
            known[topic] = {**known.get(topic, {}), **counts}
        dispatcher = self.pipeline.dispatcher
        return topic_report(
            dispatcher.received,
            dispatcher.rejected,
            self.pipeline.builder.topic_ages(),
            known,
            rates,
        )

    def stages(self) -> dict[str, StageFigures]:
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
        try:
            queue = self.last_stats = self.store.stats()
        except QueueError:
            if self.last_stats is None:
                raise
            queue = self.last_stats  # the queue cannot be read now: its last figures
        return Figures(
            queue=queue,
            sender=self.sender.stats,
            events_built=self.writer.events_handed,
            topics=self.topics(self._rates.rates),
            thread_restarts=dict(self.supervisor.restarts),
            now=self.store.now(),
            writer=self.writer.figures(),
        )

    def document(self, running: bool) -> ServiceDocument:
        """The service's figures now, with the queue's counters and the disk's figures
        taken at one moment (the accounting adds up in it)."""
        counters = {
            "send": self.sender.stats.events_sent,
            **{f"topic:{t}": n for t, n in self.pipeline.dispatcher.received.items()},
        }
        rates = self._rates.update(counters, time.monotonic())
        sender = cast(SenderFigures, self.sender.stats.as_dict())
        return service_document(
            self.options,
            {**sender, "send_rate_eps": rates.get("send", 0.0)},
            self.topics(rates),
            self.stages(),
            self.writer.events_handed,
            self.started_at,
            self.moment(running),
            self.incidents(),
        )

    def incidents(self) -> IncidentFigures:
        """The recorder's figures and the incident parts PhyCloud answered for."""
        stats = self.sender.stats
        return {
            **self.pipeline.recorder.figures(),
            "parts_sent": stats.incident_parts_sent,
            "parts_dead_lettered": stats.incident_parts_dead_lettered,
        }

    def moment(self, running: bool) -> Moment:
        """The queue's counters and the ledger of one moment: now, or, when the queue
        is busy past SNAPSHOT_WAIT_S (a commit on a slow disk) or cannot be read, the
        last moment they were read together; the writer's figures are always now."""
        writer = self.writer
        try:
            snapshot = writer.snapshot(SNAPSHOT_WAIT_S)
        except QueueError:
            snapshot = None
        if snapshot is not None:
            self.last_stats, self._last_ledger = snapshot
        ledger = self._last_ledger or writer.ledger()
        keeper = self.store.file_keeper
        return Moment(
            ledger=ledger,
            writer=writer.figures(),
            queue_file={
                "state": keeper.state.state,
                "detail": keeper.state.describe(self.store.path),
                "open_path": keeper.state.open_path,
                "restored": keeper.restored,
            },
            queue_counters={} if self.last_stats is None else dict(self.last_stats.counters),
            unwritten_counts=self.store.unwritten_counts(),
            heartbeat_at=self.store.now(),
            running=running,
            boottime=live_status.boottime(),
        )

    def write(self, running: bool) -> ServiceDocument:
        """Write the figures `status` shows (another process reads them): to the live
        status file, then into the queue file (which raises QueueError when the queue
        cannot be written; the live file says why). Without an fsync of its own: the
        row is news, not data (the next put's commit syncs it), and flash wears."""
        document = self.write_live_now(running)
        self.write_queue_row(document)
        return document

    def write_live_now(self, running: bool) -> ServiceDocument:
        """The figures now, into the live status file only (never waits long)."""
        document = self.last_document = self.document(running)
        self.write_live(document)
        return document

    def write_queue_row(self, document: ServiceDocument) -> None:
        """``document`` into the queue's heartbeat row (QueueError when it cannot)."""
        self.store.write_service_state(document, bool(document.get("running")), durable=False)
        if document["unwritten_counts"]:  # that write took them: the live file says so
            document["unwritten_counts"] = self.store.unwritten_counts()
            self.write_live(document)

    def write_live(self, document: ServiceDocument) -> None:
        if self.live_path is None:
            return
        try:
            live_status.write(self.live_path, cast(dict[str, Any], document))
            self._live_failed = False
        except OSError as exc:
            if not self._live_failed:  # once, not every beat
                log.warning("cannot write the live status %s: %s", self.live_path, exc)
            self._live_failed = True
