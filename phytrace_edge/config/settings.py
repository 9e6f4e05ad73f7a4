"""The settings: each has one name, one default, one validation rule and one doc line.

Naming: the environment variable is the upper-case name (``SAMPLE_RATE_HZ``), the TOML
key and ROS parameter the lower-case name (``sample_rate_hz``) and the flag its dashed
form (``--sample-rate-hz``). The aliases of the product's original description
(``ROBOT_ID``, ``ROBOT_TYPE``; docs/configuration.md) keep working; the primary name
wins when both are set. Defaults of a
stage's settings are the stage's own constants (its ``defaults.py``); the rest
(logging, health, metrics, shutdown) are the runtime's and live here.

This package is on the start-up path of every command: it imports nothing outside the
standard library (tests/unit/test_startup.py).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar, cast

from phytrace_edge.builder.defaults import (
    DEFAULT_ROSOUT_BURST,
    DEFAULT_ROSOUT_MIN_LEVEL,
    DEFAULT_SAMPLE_RATE_HZ,
    DEFAULT_STALE_AFTER_S,
    ROSOUT_LEVELS,
)
from phytrace_edge.config.extra_topics import topics_extra
from phytrace_edge.config.incident_triggers import incident_triggers
from phytrace_edge.config.parsers import (
    boolean,
    bridge_input,
    byte_size,
    ca_file,
    http_url,
    identifier,
    int_between,
    known_topics,
    log_level,
    namespace,
    non_negative_float,
    one_of,
    optional,
    path_value,
    positive_float,
    proxy_url,
    secret,
    topic_names,
    topic_qos,
    topic_remap,
    topic_set,
)
from phytrace_edge.incident import defaults as incident
from phytrace_edge.ingest.defaults import DEFAULT_EXTRA_MAX_ARRAY, DEFAULT_REPLAY_RATE
from phytrace_edge.ingest.qos import QosChoice
from phytrace_edge.queue import defaults as queue
from phytrace_edge.redact import Secret
from phytrace_edge.ship import defaults as ship
from phytrace_edge.units import KIB, MIB

if TYPE_CHECKING:  # the topic table: imported when a topic setting is given
    from phytrace_edge.incident.triggers import Condition
    from phytrace_edge.ingest.topics import ExtraTopic

SOURCE_TYPES = ("delivery_robot", "amr", "agv", "drone", "humanoid", "arm")
DEFAULT_SHUTDOWN_GRACE_S = 5.0
DEFAULT_HEALTH_EVENT_INTERVAL_S = 60.0

T = TypeVar("T")


class Setting:
    """One setting: its default, its parser (which is its validation rule), its doc
    line and the environment variables that are its aliases. On a ``Settings`` object
    it reads that object's value (a descriptor)."""

    __slots__ = ("aliases", "default", "doc", "key", "parse")

    def __init__(
        self, default: Any, parse: Callable[[Any], Any], doc: str, aliases: tuple[str, ...]
    ) -> None:
        self.default, self.parse, self.doc, self.aliases = default, parse, doc, aliases
        self.key = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.key = name

    def __get__(self, settings: Settings | None, owner: type | None = None) -> Any:
        return self if settings is None else settings._values[self.key]

    @property
    def env(self) -> str:
        return self.key.upper()

    @property
    def flag(self) -> str:
        return "--" + self.key.replace("_", "-")


def setting(default: T, parse: Callable[[Any], T], doc: str, *aliases: str) -> T:
    """Declare one setting of ``Settings``, typed as its value for the type checker: the
    declared type must hold both the default and what the parser returns."""
    return cast(T, Setting(default, parse, doc, aliases))  # a descriptor that reads as T


class Settings:
    """The effective configuration, validated once at start; read-only.

    Each attribute is a ``Setting`` (a descriptor): its name, default, rule and doc
    line in one declaration, which ``setting_infos`` lists for the docs, ``config``
    and the ROS parameters.
    """

    __slots__ = ("_values",)
    _values: dict[str, Any]

    phycloud_endpoint: str = setting(
        ship.DEFAULT_ENDPOINT, http_url, "PhyCloud ingestion API base URL"
    )
    phycloud_api_key: Secret = setting(Secret(""), secret, "API key sent as a Bearer token")
    phycloud_api_key_file: str | None = setting(
        None, optional(path_value), "file holding the API key (re-read on a 401 and SIGHUP)"
    )
    phycloud_proxy: str | None = setting(
        None,
        optional(proxy_url),
        "proxy for PhyCloud (or direct); default: HTTPS_PROXY etc. from the environment",
    )
    source_id: str = setting("delivery-robot-001", identifier, "unique robot id", "ROBOT_ID")
    source_type: str = setting("delivery_robot", one_of(*SOURCE_TYPES), "robot class", "ROBOT_TYPE")
    fleet_id: str | None = setting(None, optional(identifier), "fleet grouping id")
    site_id: str | None = setting(None, optional(identifier), "site or facility id")
    sample_rate_hz: float = setting(
        DEFAULT_SAMPLE_RATE_HZ, positive_float(1000), "UDM events built per second"
    )
    batch_size: int = setting(ship.DEFAULT_BATCH_SIZE, int_between(1, 10_000), "events per request")
    backlog_batch_size: int = setting(
        ship.DEFAULT_BACKLOG_BATCH_SIZE,
        int_between(1, 10_000),
        "events per request while a backlog drains",
    )
    requests_in_flight: int = setting(
        ship.DEFAULT_REQUESTS_IN_FLIGHT, int_between(1, 8), "requests sent at once"
    )
    live_share: float = setting(
        ship.DEFAULT_LIVE_SHARE,
        non_negative_float(1.0),
        "share of requests for the newest events while a backlog drains (0: oldest first)",
    )
    backfill_important_first: bool = setting(
        ship.DEFAULT_IMPORTANT_FIRST,
        boolean,
        "a backlog sends each hour's important events before its periodic ones",
    )
    bridge_input: str = setting("ros", bridge_input, "where messages come from")
    use_sim_time: bool = setting(False, boolean, "header stamps follow /clock, not the epoch")
    replay_rate: float = setting(
        DEFAULT_REPLAY_RATE,
        non_negative_float(1000),
        "bag replay speed: 1 = recorded, 0 = as fast as possible",
    )
    queue_path: str | None = setting(None, optional(path_value), "queue database file")
    queue_max_bytes: int = setting(
        queue.DEFAULT_MAX_BYTES, byte_size(1 * MIB), "byte cap of the queue (WAL included)"
    )
    queue_max_events: int | None = setting(
        None, optional(int_between(1, 10**12)), "optional event cap of the queue"
    )
    queue_on_full: str = setting(
        queue.DEFAULT_ON_FULL, one_of(*queue.ON_FULL_POLICIES), "what a full queue drops"
    )
    queue_ttl_s: float = setting(
        queue.DEFAULT_TTL_S, positive_float(10 * 365 * 86400), "queued events expire after"
    )
    queue_compression: str = setting(
        queue.DEFAULT_COMPRESSION,
        one_of(*queue.COMPRESSIONS),
        "compression of queued events at rest",
    )
    queue_sync: str = setting(
        queue.DEFAULT_SYNC, one_of(*queue.SYNC_MODES), "fsync policy of the queue"
    )
    http_compression: str = setting(
        ship.DEFAULT_HTTP_COMPRESSION,
        one_of(*ship.HTTP_COMPRESSIONS),
        "Content-Encoding of requests",
    )
    batch_max_bytes: int = setting(
        ship.DEFAULT_BATCH_MAX_BYTES, byte_size(1 * KIB), "byte bound of one request body"
    )
    flush_interval_s: float = setting(
        ship.DEFAULT_FLUSH_INTERVAL_S, positive_float(3600), "send a partial batch after"
    )
    retry_min_s: float = setting(ship.DEFAULT_RETRY_MIN_S, positive_float(3600), "first backoff")
    retry_max_s: float = setting(ship.DEFAULT_RETRY_MAX_S, positive_float(86400), "longest backoff")
    http_timeout_s: float = setting(ship.DEFAULT_HTTP_TIMEOUT_S, positive_float(600), "per request")
    shutdown_grace_s: float = setting(
        DEFAULT_SHUTDOWN_GRACE_S, positive_float(600), "time to flush at SIGTERM"
    )
    ca_bundle: str | None = setting(
        None, optional(ca_file), "CA file trusted in addition to the system's store"
    )
    client_cert: str | None = setting(
        None, optional(path_value), "client certificate (PEM) for mutual TLS"
    )
    client_key: str | None = setting(
        None, optional(path_value), "its private key (PEM); default: in CLIENT_CERT's file"
    )
    client_key_password_file: str | None = setting(
        None, optional(path_value), "file holding CLIENT_KEY's passphrase, if encrypted"
    )
    upload_max_bps: int | None = setting(
        None, optional(int_between(1, 10**12)), "upload bandwidth cap, bytes/s"
    )
    stale_after_s: float = setting(
        DEFAULT_STALE_AFTER_S, positive_float(86400), "drop a domain whose data is older"
    )
    topic_remap: dict[str, str] | None = setting(
        None, optional(topic_remap), "topic renames, /odom=/wheel/odom,..."
    )
    topics_disabled: frozenset[str] = setting(
        frozenset(), topic_set, "topics not subscribed, /scan,..."
    )
    topic_namespace: str | None = setting(
        None, optional(namespace), "prefix of the topic names, e.g. /robot1"
    )
    topic_qos: dict[str, QosChoice] | None = setting(
        None, optional(topic_qos), "per-topic QoS instead of matching, /scan=best_effort,..."
    )
    topics_extra: tuple[ExtraTopic, ...] = setting(
        (), topics_extra, "other topics sent as telemetry.topic events: '/tf rate_hz=10; ...'"
    )
    extra_max_array: int = setting(
        DEFAULT_EXTRA_MAX_ARRAY,
        int_between(1, 100_000),
        "longer arrays of an extra topic are sent as {len, head}",
    )
    rosout_min_level: str = setting(
        DEFAULT_ROSOUT_MIN_LEVEL, one_of(*ROSOUT_LEVELS), "/rosout records sent from this level"
    )
    rosout_burst: int = setting(
        DEFAULT_ROSOUT_BURST,
        int_between(1, 100_000),
        "/rosout records per logger per minute; the rest are counted",
    )
    incident_recording: bool = setting(
        True, boolean, "keep the incident topics' last seconds and record incidents"
    )
    incident_topics: tuple[str, ...] = setting(
        incident.DEFAULT_INCIDENT_TOPICS,
        topic_names,
        "topics kept at full rate for incidents (the table's or TOPICS_EXTRA's)",
    )
    incident_before_s: float = setting(
        incident.DEFAULT_INCIDENT_BEFORE_S, positive_float(600), "an incident's seconds before"
    )
    incident_after_s: float = setting(
        incident.DEFAULT_INCIDENT_AFTER_S, positive_float(600), "an incident's seconds after"
    )
    incident_buffer_max_bytes: int = setting(
        incident.DEFAULT_INCIDENT_BUFFER_MAX_BYTES,
        byte_size(64 * KIB, 4 * 1024 * MIB),
        "memory bound of the incident window; beyond it the oldest samples go, counted",
    )
    incident_diagnostics_level: str = setting(
        incident.DEFAULT_INCIDENT_DIAGNOSTICS_LEVEL,
        one_of("warn", "error", "stale", "off"),
        "a /diagnostics status entering this level opens an incident",
    )
    incident_rosout_level: str = setting(
        incident.DEFAULT_INCIDENT_ROSOUT_LEVEL,
        one_of("error", "fatal", "off"),
        "a /rosout record at this level opens an incident",
    )
    incident_triggers: tuple[Condition, ...] = setting(
        (), incident_triggers, "topic conditions that open an incident: '/estop data == true'"
    )
    incident_max_per_hour: int = setting(
        incident.DEFAULT_INCIDENT_MAX_PER_HOUR,
        int_between(1, 3600),
        "incidents opened per hour at most; more triggers are counted",
    )
    incident_max_s: float = setting(
        incident.DEFAULT_INCIDENT_MAX_S,
        positive_float(3600),
        "later triggers extend a window at most this far past its first",
    )
    health_event_interval_s: float = setting(
        DEFAULT_HEALTH_EVENT_INTERVAL_S,
        non_negative_float(86400),
        "a bridge.health event every this many seconds and on a change (0 = none)",
    )
    metrics_port: int = setting(0, int_between(0, 65535), "Prometheus endpoint port, 0 = off")
    metrics_host: str = setting("127.0.0.1", identifier, "address the metrics endpoint binds")
    health_stale_s: float = setting(
        15.0, positive_float(3600), "status: heartbeat older than this means hung or dead"
    )
    health_no_progress_s: float = setting(
        300.0, positive_float(86400), "status: events waiting, nothing sent for this long"
    )
    queue_warn_fraction: float = setting(
        0.8, positive_float(1.0), "status: unhealthy above this fraction of the byte cap"
    )
    log_level: str = setting("INFO", log_level, "log threshold")
    log_format: str = setting("text", one_of("text", "json"), "log line format")

    @property
    def topics(self) -> dict[str, str]:
        """Enabled topics: canonical name -> name subscribed on the robot (a remap wins
        over the namespace)."""
        remap = self.topic_remap or {}
        prefix = self.topic_namespace or ""
        return {
            t: remap.get(t, prefix + t) for t in known_topics() if t not in self.topics_disabled
        }

    @property
    def extra_topics(self) -> dict[str, str]:
        """TOPICS_EXTRA's topics: name -> name subscribed on the robot (namespaced)."""
        prefix = self.topic_namespace or ""
        return {extra.name: prefix + extra.name for extra in self.topics_extra}

    def __init__(self, **values: Any) -> None:
        unknown = set(values) - set(_SETTINGS)
        if unknown:
            raise TypeError(f"unknown settings: {sorted(unknown)}")
        merged = {key: values.get(key, s.default) for key, s in _SETTINGS.items()}
        object.__setattr__(self, "_values", merged)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Settings are read-only; use replace()")

    def replace(self, **changes: Any) -> Settings:
        """A copy with ``changes``."""
        return Settings(**{**self._values, **changes})

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Settings) and other._values == self._values

    def __hash__(self) -> int:
        return hash(tuple(sorted((k, repr(v)) for k, v in self._values.items())))

    def __repr__(self) -> str:
        return "Settings(" + ", ".join(f"{k}={v!r}" for k, v in self._values.items()) + ")"


_SETTINGS: dict[str, Setting] = {
    name: value for name, value in vars(Settings).items() if isinstance(value, Setting)
}


def setting_infos() -> list[Setting]:
    """Every setting, in declaration order."""
    return list(_SETTINGS.values())
