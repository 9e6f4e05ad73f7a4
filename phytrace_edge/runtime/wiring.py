"""The composition root: the one place the parts are built and connected.

``runtime/options.py`` turns the settings into each part's options; this module
builds the parts from them: the pipeline (source -> dispatcher -> builder -> sampler
-> emit) for ``run``, ``run_simulation`` and the tests, the service around it, and the
queue and sender that ``drain``, ``import`` and ``export`` use. These two modules
read ``Settings`` (with ``runtime/health.py``, which reads its own four thresholds so
that ``status`` starts without every stage's options).

The dependency rule of the package (checked by ``tests/unit/test_architecture.py``),
each component importing only those to its right::

    cli -> runtime -> config -> ship -> queue
                             -> incident -> builder -> ingest -> sim
    cli -> handcarry -> queue
    everything -> udm, units, redact, errors, _version, host_clock, host_memory, durable

``stub`` (the PhyCloud dev stub) stands apart: only the CLI starts it, and it uses only
``udm`` and ``errors``. No stage imports ``config`` or ``runtime``; the simulator
imports nothing of the bridge.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phytrace_edge import host_clock
from phytrace_edge.builder.builder import SystemClock, UDMBuilder
from phytrace_edge.builder.sampler import Sampler, TickInput
from phytrace_edge.config import Settings
from phytrace_edge.errors import QueueError
from phytrace_edge.host_memory import give_back_free_memory
from phytrace_edge.incident.recorder import IncidentRecorder
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.generic import message_data
from phytrace_edge.ingest.readings import Reading
from phytrace_edge.ingest.sources.base import Source
from phytrace_edge.ingest.sources.registry import create_source
from phytrace_edge.queue.defaults import OnFull
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.outbound.ownership import ServiceLock
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime import live_status, options
from phytrace_edge.runtime.health_events import HealthEvents
from phytrace_edge.runtime.heartbeat import Heartbeat
from phytrace_edge.runtime.pipeline import Pipeline
from phytrace_edge.runtime.preflight import warn_if_not_on_a_volume
from phytrace_edge.runtime.service import BridgeService
from phytrace_edge.runtime.supervisor import Supervisor
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport, Transport
from phytrace_edge.udm.schema import prepare_validator
from phytrace_edge.udm.types import Built, UdmEvent

# A file being imported is staged a chunk at a time: never full, and events days old
# must not expire while staged.
STAGING_LIMITS = QueueLimits(on_full=OnFull.DROP_NEWEST, ttl_s=10 * 365 * 86400.0)
log = logging.getLogger(__name__)

STAGING_LEASE_S = 600.0  # a chunk of a file is sent before its claims lapse


def build_pipeline(s: Settings, source: Source, emit: Callable[[Built], None]) -> Pipeline:
    """``source`` -> dispatcher -> builder -> sampler -> ``emit``. At each tick the
    sampler takes from the source (``before_tick``) and hands what it took to the
    dispatcher, then builds: one way, the source calling nothing back."""
    # a bag's events carry bag time: only this machine's clock can be unsynchronized
    unsynchronized = None if source.keeps_time else host_clock.unsynchronized
    clock = source.clock or SystemClock()  # one timeline for events and incidents
    builder = UDMBuilder(options.builder_options(s), clock, source.field_types, unsynchronized)
    # a live input takes the window topics' messages at the tick: one received before a
    # window's end can come a tick after one received later (a bag's come in order)
    settle_s = 0.0 if source.keeps_time else max(1.0, 2.0 / s.sample_rate_hz)
    recorder = IncidentRecorder(
        options.incident_options(s),
        builder.identity,
        s.batch_max_bytes,
        clock,
        unsynchronized,
        settle_s=settle_s,
    )

    def on_reading(topic: str, reading: Reading, age_s: float) -> None:
        builder.add_reading(topic, reading, age_s)
        recorder.observe(topic, reading, age_s)

    def on_other(topic: str, msg: Any, age_s: float) -> None:  # a TOPICS_EXTRA topic
        builder.add_message(topic, msg, age_s)
        if topic in recorder.watched:
            data = message_data(msg, source.field_types, s.extra_max_array)
            recorder.observe(topic, data, age_s)

    dispatcher = Dispatcher(on_reading, on_other)
    tick_input = TickInput(source.before_tick, dispatcher.on_taken)
    sampler = Sampler(builder, emit, s.sample_rate_hz, tick_input, incidents=recorder.take_closed)
    return Pipeline(source, dispatcher, builder, sampler, recorder, emit)


def simulation_pipeline(
    s: Settings | None, emit: Callable[[Built], None], *, seed: int, realtime: bool, max_ticks: int
) -> Pipeline:
    """The simulated robot through the ``ros`` input's path (``run_simulation``)."""
    simulated = (s or Settings()).replace(bridge_input="sim")
    source_options = options.source_options(
        simulated, {}, seed=seed, virtual_time=not realtime, max_ticks=max_ticks
    )
    return build_pipeline(simulated, create_source(source_options), emit)


def open_queue(s: Settings) -> QueueStore:
    """The queue named by the settings."""
    q = options.queue_options(s)
    return QueueStore.open(
        q.path, limits=q.limits, compression=q.compression, sync=q.sync, lease_s=q.lease_s
    )


def http_transport(s: Settings, env: Mapping[str, str]) -> HttpTransport:
    """The transport to PhyCloud as the settings and ``env`` (the process environment:
    proxies, systemd credentials) say."""
    link = options.link_options(s, env)
    return HttpTransport(
        link.endpoint,
        options.api_key(s, env),
        link.timeout_s,
        tls_options=link.tls,
        proxy=link.proxy,
    )


@dataclass(frozen=True)
class Shipping:
    """A queue and the sender that empties it (``drain``, ``import``)."""

    store: QueueStore
    sender: Sender


@contextmanager
def shipping(s: Settings, env: Mapping[str, str]) -> Iterator[Shipping]:
    """The robot's queue and its sender, as ``run`` would send it (``drain``)."""
    with open_queue(s) as store, _sending(s, env, store, options.send_policy(s)) as parts:
        yield parts


@contextmanager
def staging(s: Settings, env: Mapping[str, str], path: Path) -> Iterator[Shipping]:
    """A staging queue at ``path`` and a sender that sends it strictly oldest first
    (``import``: the staging queue only feeds the sender)."""
    policy = dataclasses.replace(options.send_policy(s), live_share=0.0)
    with (
        QueueStore.open(path, limits=STAGING_LIMITS, lease_s=STAGING_LEASE_S) as store,
        _sending(s, env, store, policy) as parts,
    ):
        yield parts


@contextmanager
def _sending(
    s: Settings, env: Mapping[str, str], store: QueueStore, policy: SendPolicy
) -> Iterator[Shipping]:
    sender = Sender(store, http_transport(s, env), policy)
    try:
        yield Shipping(store, sender)
    finally:
        sender.transport.close()


def build_service(
    s: Settings,
    env: Mapping[str, str],
    ros_args: Sequence[str] = (),
    transport: Transport | None = None,
    on_event: Callable[[UdmEvent], None] | None = None,
) -> BridgeService:
    """Every part of the bridge, wired; ``transport`` replaces HTTP in tests and
    ``on_event`` sees every event built."""
    path = options.queue_path(s)
    warn_if_not_on_a_volume(path, env)
    source = create_source(options.source_options(s, env, ros_args))
    refuse_a_queue_that_went_missing(str(path), env)
    lock = ServiceLock(path)  # one `run` per queue file
    try:
        store = open_queue(s)
    except BaseException:
        lock.release()
        raise
    try:
        carry_over_unwritten_counts(store, str(path), env)
        live_path = live_status.writable_path(str(path), env)
        service = _service(
            s, source, store, transport or http_transport(s, env), on_event, live_path
        )
    except BaseException:
        store.close()
        lock.release()
        raise
    service.on_stopped(lock.release)
    prepare_validator()  # its one-off peak now, then handed back
    give_back_free_memory()
    return service


def read_api_key_again(service: BridgeService) -> None:
    """SIGHUP: the key file read again (or a line saying why it cannot be)."""
    transport = service.sender.transport
    if isinstance(transport, HttpTransport):
        log.warning(transport.api_key.reload_on_hangup())
    else:
        log.warning("SIGHUP: ignored (no HTTP transport)")


def refuse_a_queue_that_went_missing(path: str, env: Mapping[str, str]) -> None:
    """A bridge ran on this queue earlier in this boot (its live status says so), and
    the file is not there now: its volume was unmounted, or its folder moved or
    removed. Making a new empty queue there would hide the old one's events."""
    found = live_status.find(path, env)
    if found is None or Path(path).exists():
        return
    live_path, document = found
    depth = (document.get("queue_counters") or {}).get("depth", "?")
    raise QueueError(
        f"queue {path} is missing, but a bridge (pid {document.get('pid', '?')}) used it "
        f"earlier in this boot with {depth} event(s) queued: is its volume mounted, its "
        f"folder where it was? To start a fresh queue there, remove {live_path}"
    )


def carry_over_unwritten_counts(store: QueueStore, path: str, env: Mapping[str, str]) -> None:
    """Counts that the last run of this boot could not write to its queue before it
    stopped (its disk failed: ``unwritable`` events), kept in its live status file:
    into the queue now, so that the accounting adds up across the restart."""
    found = live_status.find(path, env)
    if found is None or found[1].get("running"):
        return  # none, or a run that was killed: its last figures are only a snapshot
    live_path, document = found
    counts = {k: int(v) for k, v in (document.get("unwritten_counts") or {}).items() if v}
    if counts:
        store.defer_counts(counts)
        log.warning("the last run could not write these counts to the queue: %s; added now", counts)
        live_status.remove(live_path)  # once: this run writes its own at its start


def _service(
    s: Settings,
    source: Source,
    store: QueueStore,
    transport: Transport,
    on_event: Callable[[UdmEvent], None] | None,
    live_path: str | None,
) -> BridgeService:
    link = transport.figures() if isinstance(transport, HttpTransport) else {}
    service_options = dataclasses.replace(options.service_options(s), link=link)
    started_at = store.now()
    sender = Sender(store, transport, options.send_policy(s))
    writer = QueueWriter(store, wait_for_disk=source.keeps_time, on_event=on_event)
    pipeline = build_pipeline(s, source, writer.emit)
    supervisor = Supervisor()
    heartbeat = Heartbeat(
        service_options, pipeline, store, sender, writer, supervisor, started_at, live_path
    )
    health_events = HealthEvents(
        service_options.health_event_interval_s,
        service_options.thresholds,
        pipeline.builder.identity,
        started_at,
        writer.emit,
    )
    return BridgeService(
        service_options, pipeline, store, sender, writer, heartbeat, health_events, supervisor
    )
