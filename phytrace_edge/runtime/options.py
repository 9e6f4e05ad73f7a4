"""The settings, turned into each part's plain options: with ``runtime/wiring.py`` the
only module that reads ``Settings`` (each stage owns its options' defaults). The one
exception is the health thresholds, read by ``runtime/health.py`` itself so that
``status`` does not import every stage's options to start.

It imports only the options of the stages, never the stages themselves.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.config import Settings, setting_infos
from phytrace_edge.errors import ConfigError
from phytrace_edge.incident.options import IncidentOptions
from phytrace_edge.ingest.sources.base import SourceOptions
from phytrace_edge.ingest.sources.dds_env import domain_settings
from phytrace_edge.ingest.topics import TOPIC_NAMES
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.redact import redact_url
from phytrace_edge.runtime import health, marks
from phytrace_edge.runtime.health import Thresholds
from phytrace_edge.runtime.logs import configure_logging as configure_logs
from phytrace_edge.ship.api_key import CREDENTIAL_NAME, ApiKey, readable_by_others
from phytrace_edge.ship.options import SendPolicy, claim_lease_s
from phytrace_edge.ship.proxy import proxy_for
from phytrace_edge.ship.tls import ClientCertificate, TlsOptions

log = logging.getLogger(__name__)

MIN_STALL_S = 30.0


@dataclass(frozen=True)
class ServiceOptions:
    """What the service itself needs to know (the rest is in its parts)."""

    input_label: str  # BRIDGE_INPUT as configured
    source_id: str
    source_type: str
    endpoint_host: str
    sample_rate_hz: float
    shutdown_grace_s: float
    stall_after_s: float = MIN_STALL_S  # a worker without progress this long is stuck
    metrics_host: str = "127.0.0.1"
    metrics_port: int = 0
    health_event_interval_s: float = 0.0  # 0: no bridge.health events
    thresholds: Thresholds | None = None  # what the health events judge by
    link: Mapping[str, Any] = field(default_factory=dict)  # HttpTransport.figures()
    marks_dir: Path | None = None  # where ``phytrace-edge mark`` leaves marks (runtime/marks.py)
    incident_before_s: float = 30.0  # a mark older than this is past the window


@dataclass(frozen=True)
class QueueOptions:
    """How the queue file is opened (``QueueStore.open``'s arguments)."""

    path: Path
    limits: QueueLimits
    compression: str
    sync: str
    lease_s: float


def configure_logging(s: Settings, env: Mapping[str, str]) -> None:
    """Logging as LOG_LEVEL and LOG_FORMAT say, with the API key masked; ``env`` tells
    whether stderr is systemd's journal."""
    configure_logs(s.log_level, s.log_format, [s.phycloud_api_key.reveal()], env)


def identity(s: Settings) -> Identity:
    return Identity(s.source_id, s.source_type, s.fleet_id, s.site_id)


def builder_options(s: Settings) -> BuilderOptions:
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


def incident_options(s: Settings) -> IncidentOptions:
    """The INCIDENT_* settings. A window topic or trigger condition must be a topic the
    bridge hears: the table's (a disabled one is left out of the window) or
    TOPICS_EXTRA's."""
    extra = {topic.name for topic in s.topics_extra}
    unknown = [
        topic
        for topic in (*s.incident_topics, *(c.topic for c in s.incident_triggers))
        if topic not in extra and topic not in TOPIC_NAMES
    ]
    if unknown:
        raise ConfigError(
            f"INCIDENT_TOPICS/INCIDENT_TRIGGERS name {', '.join(unknown)}: not a topic of "
            "the table, nor of TOPICS_EXTRA (add it there to hear it)"
        )
    heard = set(s.topics) | extra
    return IncidentOptions(
        enabled=s.incident_recording,
        topics=tuple(topic for topic in s.incident_topics if topic in heard),
        before_s=s.incident_before_s,
        after_s=s.incident_after_s,
        buffer_max_bytes=s.incident_buffer_max_bytes,
        max_per_hour=s.incident_max_per_hour,
        max_s=s.incident_max_s,
        diagnostics_level=_unless_off(s.incident_diagnostics_level),
        rosout_level=_unless_off(s.incident_rosout_level),
        conditions=s.incident_triggers,
    )


def _unless_off(level: str) -> str | None:
    return None if level == "off" else level


def source_options(
    s: Settings, env: Mapping[str, str], ros_args: Sequence[str] = (), **simulator: Any
) -> SourceOptions:
    """BRIDGE_INPUT and the topic settings; ``env`` is read for ROS 2's DDS variables."""
    kind, _, bag_path = s.bridge_input.partition(":")
    domain_id, localhost_only = 0, False
    recorded = incident_options(s)
    full_rate = frozenset(recorded.topics) if recorded.enabled else frozenset()
    every_message = (
        frozenset(c.topic for c in recorded.conditions) - full_rate
        if recorded.enabled
        else frozenset()
    )
    if kind == "dds":
        domain_id, localhost_only = domain_settings(env)
    return SourceOptions(
        kind=kind,
        topics=s.topics,
        extra_topics={
            extra.name: (s.extra_topics[extra.name], extra.type_name) for extra in s.topics_extra
        },
        qos_overrides=s.topic_qos or {},
        every_message=every_message,
        full_rate=full_rate,
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
    parameters: dict[str, tuple[Any, str]] = {}
    for info in setting_infos():
        value = getattr(s, info.key)
        if info.key == "phycloud_api_key" or value is None or value in ((), frozenset(), {}):
            continue
        if not isinstance(value, (bool, int, float, str)):
            value = str(value)
        parameters[info.key] = (value, info.doc)
    return parameters


def queue_path(s: Settings) -> Path:
    """QUEUE_PATH (the CLI's loading fills in its default under the state directory)."""
    if s.queue_path is None:
        raise ConfigError("QUEUE_PATH is not set")
    return Path(s.queue_path)


def queue_options(s: Settings) -> QueueOptions:
    """The queue named by the settings, its claims leased as the send policy needs."""
    return QueueOptions(
        path=queue_path(s),
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


@dataclass(frozen=True)
class LinkOptions:
    """How the bridge reaches PhyCloud: PHYCLOUD_ENDPOINT, HTTP_TIMEOUT_S, the proxy
    (PHYCLOUD_PROXY or the environment's) and TLS (CA_BUNDLE, CLIENT_CERT...)."""

    endpoint: str
    timeout_s: float
    proxy: str | None
    tls: TlsOptions


def link_options(s: Settings, env: Mapping[str, str]) -> LinkOptions:
    client = (
        ClientCertificate(s.client_cert, s.client_key, s.client_key_password_file)
        if s.client_cert
        else None
    )
    if client is None and (s.client_key or s.client_key_password_file):
        raise ConfigError("CLIENT_KEY and CLIENT_KEY_PASSWORD_FILE need CLIENT_CERT")
    return LinkOptions(
        s.phycloud_endpoint,
        s.http_timeout_s,
        proxy_for(s.phycloud_endpoint, env, s.phycloud_proxy),
        TlsOptions(s.ca_bundle, client),
    )


def api_key(s: Settings, env: Mapping[str, str]) -> ApiKey:
    """The API key: PHYCLOUD_API_KEY, or the file PHYCLOUD_API_KEY_FILE names, or
    systemd's credential ``phycloud_api_key`` (``LoadCredential=``) when neither is
    set. A file readable by other users gets a warning."""
    if s.phycloud_api_key and s.phycloud_api_key_file:
        raise ConfigError("PHYCLOUD_API_KEY and PHYCLOUD_API_KEY_FILE are both set: keep one")
    if s.phycloud_api_key_file:
        key = ApiKey.from_file(s.phycloud_api_key_file, "PHYCLOUD_API_KEY_FILE")
    elif not s.phycloud_api_key and env.get("CREDENTIALS_DIRECTORY"):
        credential = Path(env["CREDENTIALS_DIRECTORY"].split(":")[0]) / CREDENTIAL_NAME
        try:
            credential.stat()
        except FileNotFoundError:  # credentials, but not the key: it is not required
            return ApiKey(s.phycloud_api_key)
        except OSError:
            pass  # cannot be read: from_file says why, in one line
        key = ApiKey.from_file(str(credential), f"systemd credential {CREDENTIAL_NAME}")
    else:
        return ApiKey(s.phycloud_api_key)
    warning = readable_by_others(str(key.path))
    if warning:
        log.warning(warning)
    return key


def service_options(s: Settings) -> ServiceOptions:
    return ServiceOptions(
        input_label=s.bridge_input,
        source_id=s.source_id,
        source_type=s.source_type,
        endpoint_host=urlsplit(redact_url(s.phycloud_endpoint)).netloc,
        sample_rate_hz=s.sample_rate_hz,
        shutdown_grace_s=s.shutdown_grace_s,
        stall_after_s=max(MIN_STALL_S, 3 * s.http_timeout_s),
        metrics_host=s.metrics_host,
        metrics_port=s.metrics_port,
        # a bag replay is history, not a running robot: no health events of its own
        health_event_interval_s=0.0
        if s.bridge_input.startswith("bag:")
        else (s.health_event_interval_s),
        thresholds=health.thresholds(s),
        marks_dir=marks.marks_dir(queue_path(s)),
        incident_before_s=s.incident_before_s,
    )
