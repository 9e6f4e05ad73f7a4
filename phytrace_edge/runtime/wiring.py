"""The composition root: the one module that reads ``Settings`` and wires the stages.

It turns the settings into each stage's plain options (whose defaults the stages own)
and builds the parts of the service. Everything else receives plain values.

The dependency rule of the package (checked by ``tests/unit/test_architecture.py``),
each component importing only those to its right::

    cli -> runtime -> config -> ship -> queue
                             -> builder -> ingest -> sim
    everything -> udm, units, redact, errors

``stub`` (the PhyCloud dev stub) stands apart: only the CLI starts it, and it uses only
``udm`` and ``errors``. No stage imports ``config`` or ``runtime``; the simulator
imports nothing of the bridge.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

# The parts are imported where they are built: ``status`` reads its settings through
# this module and must start fast (stdlib only at import, docs/benchmarks.md).
TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing
if TYPE_CHECKING:
    from typing import Any

    from phytrace_edge.builder.options import BuilderOptions, Identity
    from phytrace_edge.config import Settings
    from phytrace_edge.ingest.sources.base import SourceOptions
    from phytrace_edge.queue.store import QueueStore
    from phytrace_edge.runtime.health import Thresholds
    from phytrace_edge.runtime.service import BridgeService, ServiceOptions
    from phytrace_edge.ship.options import SendPolicy
    from phytrace_edge.ship.transport import HttpTransport, Transport

MIN_STALL_S = 30.0


def configure_logging(s: Settings, env: Mapping[str, str]) -> None:
    """Logging as LOG_LEVEL and LOG_FORMAT say, with the API key masked; ``env`` tells
    whether stderr is systemd's journal."""
    from phytrace_edge.runtime.logs import configure_logging as configure

    configure(s.log_level, s.log_format, [s.phycloud_api_key.reveal()], env)


def identity(s: Settings) -> Identity:
    from phytrace_edge.builder.options import Identity

    return Identity(s.source_id, s.source_type, s.fleet_id, s.site_id)


def builder_options(s: Settings) -> BuilderOptions:
    from phytrace_edge.builder.options import BuilderOptions

    return BuilderOptions(
        identity(s),
        s.sample_rate_hz,
        s.stale_after_s,
        s.use_sim_time,
        extra_topics=s.topics_extra,
        extra_max_array=s.extra_max_array,
        rosout_min_level=s.rosout_min_level,
        rosout_burst=s.rosout_burst,
    )


def source_options(
    s: Settings, env: Mapping[str, str], ros_args: Sequence[str] = (), **simulator: Any
) -> SourceOptions:
    """BRIDGE_INPUT and the topic settings; ``env`` is read for ROS 2's DDS variables."""
    from phytrace_edge.ingest.sources.base import SourceOptions

    kind, _, bag_path = s.bridge_input.partition(":")
    domain_id, localhost_only = 0, False
    if kind == "dds":
        from phytrace_edge.ingest.sources.dds import domain_settings

        domain_id, localhost_only = domain_settings(env)
    return SourceOptions(
        kind=kind,
        topics=s.topics,
        extra_topics={
            extra.name: (s.extra_topics[extra.name], extra.type_name) for extra in s.topics_extra
        },
        qos_overrides=s.topic_qos or {},
        bag_path=bag_path,
        replay_rate=s.replay_rate,
        ros_args=tuple(ros_args),
        parameters=ros_parameter_values(s) if kind in ("ros", "sim") else {},
        dds_domain_id=domain_id,
        dds_localhost_only=localhost_only,
        dds_cyclonedds_uri=env.get("CYCLONEDDS_URI", "") if kind == "dds" else "",
        **simulator,
    )


def ros_parameter_values(s: Settings) -> dict[str, tuple[Any, str]]:
    """Every setting that has a value, as a ROS parameter (name -> (value, its doc
    line)), for ``ros2 param list/get``; never the API key. A value ROS has no type
    for (a table, a set) is given as text."""
    from phytrace_edge.config import setting_infos

    parameters: dict[str, tuple[Any, str]] = {}
    for info in setting_infos():
        value = getattr(s, info.key)
        if info.key == "phycloud_api_key" or value is None or value in ((), frozenset(), {}):
            continue
        if not isinstance(value, (bool, int, float, str)):
            value = str(value)
        parameters[info.key] = (value, info.doc)
    return parameters


def queue_path(s: Settings) -> str:
    return str(s.queue_path)


def open_queue(s: Settings) -> QueueStore:
    """The queue named by the settings, its claims leased as the send policy needs."""
    from phytrace_edge.queue.options import QueueLimits
    from phytrace_edge.queue.store import QueueStore
    from phytrace_edge.ship.options import claim_lease_s

    return QueueStore.open(
        queue_path(s),
        limits=QueueLimits(
            max_bytes=s.queue_max_bytes,
            max_events=s.queue_max_events,
            on_full=s.queue_on_full,
            ttl_s=s.queue_ttl_s,
        ),
        compression=s.queue_compression,
        sync=s.queue_sync,
        lease_s=claim_lease_s(send_policy(s), s.http_timeout_s),
    )


def send_policy(s: Settings) -> SendPolicy:
    from phytrace_edge.ship.options import SendPolicy

    return SendPolicy(
        batch_size=s.batch_size,
        backlog_batch_size=s.backlog_batch_size,
        requests_in_flight=s.requests_in_flight,
        live_share=s.live_share,
        important_first=s.backfill_important_first,
        batch_max_bytes=s.batch_max_bytes,
        flush_interval_s=s.flush_interval_s,
        retry_min_s=s.retry_min_s,
        retry_max_s=s.retry_max_s,
        http_compression=s.http_compression,
        upload_max_bps=s.upload_max_bps,
    )


def http_transport(s: Settings) -> HttpTransport:
    from phytrace_edge.ship.transport import HttpTransport

    return HttpTransport(s.phycloud_endpoint, s.phycloud_api_key, s.http_timeout_s, s.ca_bundle)


def health_thresholds(s: Settings) -> Thresholds:
    from phytrace_edge.runtime.health import Thresholds

    return Thresholds(
        s.health_stale_s, s.health_no_progress_s, s.queue_warn_fraction, s.queue_max_bytes
    )


def service_options(s: Settings) -> ServiceOptions:
    from urllib.parse import urlsplit

    from phytrace_edge.runtime.service import ServiceOptions

    return ServiceOptions(
        input_label=s.bridge_input,
        source_id=s.source_id,
        source_type=s.source_type,
        endpoint_host=urlsplit(s.phycloud_endpoint).netloc,
        sample_rate_hz=s.sample_rate_hz,
        shutdown_grace_s=s.shutdown_grace_s,
        stall_after_s=max(MIN_STALL_S, 3 * s.http_timeout_s),
        metrics_host=s.metrics_host,
        metrics_port=s.metrics_port,
        # a bag replay is history, not a running robot: no health events of its own
        health_event_interval_s=0.0
        if s.bridge_input.startswith("bag:")
        else (s.health_event_interval_s),
        thresholds=health_thresholds(s),
    )


def build_service(
    s: Settings,
    env: Mapping[str, str],
    ros_args: Sequence[str] = (),
    transport: Transport | None = None,
    on_event: Callable[[dict[str, Any]], None] | None = None,
) -> BridgeService:
    """Every part of the bridge, wired; ``transport`` replaces HTTP in tests."""
    from pathlib import Path

    from phytrace_edge.builder.builder import UDMBuilder
    from phytrace_edge.ingest.sources.registry import create_source
    from phytrace_edge.queue.ownership import ServiceLock
    from phytrace_edge.runtime.preflight import warn_if_not_on_a_volume
    from phytrace_edge.runtime.service import BridgeService
    from phytrace_edge.ship.sender import Sender

    warn_if_not_on_a_volume(Path(queue_path(s)), env)
    source = create_source(source_options(s, env, ros_args))
    lock = ServiceLock(Path(queue_path(s)))  # one `run` per queue file
    try:
        store = open_queue(s)
    except BaseException:
        lock.release()
        raise
    try:
        sender = Sender(store, transport or http_transport(s), send_policy(s))
        builder = UDMBuilder(builder_options(s), source.clock, source.field_types)
        service = BridgeService(service_options(s), store, sender, source, builder, on_event)
    except BaseException:
        store.close()
        lock.release()
        raise
    service.on_stopped(lock.release)
    return service
