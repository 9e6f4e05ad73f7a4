"""Settings: every knob has one name, one default, one validation rule and one doc line.

Sources, highest first: command-line flag, environment variable, config file (TOML),
ROS parameter, default. ``load_settings`` is a pure function from those sources to a
frozen ``Settings``; components receive plain values and never read the environment.

Naming: the environment variable is the upper-case name (``SAMPLE_RATE_HZ``), the TOML
key and ROS parameter the lower-case name (``sample_rate_hz``) and the flag its dashed
form (``--sample-rate-hz``). The reference guide's aliases (``ROBOT_ID``,
``ROBOT_TYPE``) keep working; the primary name wins when both are set. An empty
environment variable counts as unset, because compose files pass ``${FLEET_ID}``
through as an empty string when the operator did not set it.
"""

from __future__ import annotations

import itertools
import math
import os
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.ros import QosChoice
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on 3.10 only
    import tomli as tomllib

SOURCE_TYPES = ("delivery_robot", "amr", "agv", "drone", "humanoid", "arm")
KNOWN_TOPICS = tuple(TOPIC_BY_NAME)

KIB = 1024
MIB = 1024 * KIB
GIB = 1024 * MIB
DEFAULT_ENDPOINT = "http://localhost:8000/api/v1"
DEFAULT_SAMPLE_RATE_HZ = 5.0
DEFAULT_BATCH_SIZE = 10
DEFAULT_QUEUE_MAX_BYTES = 1 * GIB
DEFAULT_QUEUE_TTL_S = 7 * 24 * 3600.0
DEFAULT_BATCH_MAX_BYTES = 1 * MIB
DEFAULT_FLUSH_INTERVAL_S = 2.0
DEFAULT_RETRY_MIN_S = 0.5
DEFAULT_RETRY_MAX_S = 60.0
DEFAULT_HTTP_TIMEOUT_S = 10.0
DEFAULT_STALE_AFTER_S = 5.0
DEFAULT_SHUTDOWN_GRACE_S = 5.0


class Secret:
    """A string that never shows itself in a repr, str, log line or exception."""

    __slots__ = ("_value",)

    def __init__(self, value: str) -> None:
        self._value = value

    def reveal(self) -> str:
        """The real value, for the one place that must send it (the HTTP header)."""
        return self._value

    def __bool__(self) -> bool:
        return bool(self._value)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Secret) and other._value == self._value

    def __hash__(self) -> int:
        return hash(self._value)

    def __str__(self) -> str:
        return "***" if self._value else ""

    def __repr__(self) -> str:
        return f"Secret({str(self)!r})"


# ---------------------------------------------------------------- value parsers
# Each parser takes the raw value (a string from env/flags, or a TOML/ROS value) and
# returns the typed value or raises ValueError whose text says what is allowed.


def _number(raw: Any, kind: type) -> Any:
    if isinstance(raw, bool):
        raise ValueError
    try:
        value = kind(raw)
    except (TypeError, ValueError) as exc:
        raise ValueError from exc
    if kind is float and not math.isfinite(value):
        raise ValueError
    return value


def positive_float(upper: float) -> Callable[[Any], float]:
    def parse(raw: Any) -> float:
        try:
            value = _number(raw, float)
        except ValueError:
            value = -1.0
        if not 0 < value <= upper:
            raise ValueError(f"a number > 0 and <= {upper:g}")
        return value

    return parse


def non_negative_float(upper: float) -> Callable[[Any], float]:
    def parse(raw: Any) -> float:
        try:
            value = _number(raw, float)
        except ValueError:
            value = -1.0
        if not 0 <= value <= upper:
            raise ValueError(f"a number from 0 to {upper:g}")
        return value

    return parse


def int_between(lower: int, upper: int) -> Callable[[Any], int]:
    def parse(raw: Any) -> int:
        try:
            value = _number(raw, int)
        except ValueError:
            value = lower - 1
        if not lower <= value <= upper:
            raise ValueError(f"a whole number from {lower} to {upper}")
        return value

    return parse


def optional(parse: Callable[[Any], Any]) -> Callable[[Any], Any]:
    def parse_optional(raw: Any) -> Any:
        if raw is None or (isinstance(raw, str) and raw.strip().lower() in ("", "none")):
            return None
        try:
            return parse(raw)
        except ValueError as exc:
            raise ValueError(f"{exc} (or none)") from exc

    return parse_optional


def one_of(*choices: str) -> Callable[[Any], str]:
    def parse(raw: Any) -> str:
        value = str(raw).strip().lower()
        if value not in choices:
            raise ValueError("one of " + ", ".join(choices))
        return value

    return parse


_SIZE = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([kmgt]?i?b?)?\s*$", re.IGNORECASE)


def byte_size(lower: int) -> Callable[[Any], int]:
    """Bytes as a number or with a unit: ``1048576``, ``512MiB``, ``1GiB``, ``1.5GB``."""

    def parse(raw: Any) -> int:
        allowed = f"a size of at least {format_bytes(lower)}, like 1048576, 512MiB or 1GiB"
        match = _SIZE.match(str(raw)) if not isinstance(raw, bool) else None
        if not match:
            raise ValueError(allowed)
        unit = (match.group(2) or "").lower()
        base = 1024 if "i" in unit else 1000
        scale = base ** "bkmgt".index(unit[0]) if unit and unit[0] != "b" else 1
        value = int(float(match.group(1)) * scale)
        if value < lower:
            raise ValueError(allowed)
        return value

    return parse


def format_bytes(n: float) -> str:
    """``1073741824`` -> ``1 GiB``; used in messages and status output."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" or n == int(n) else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def http_url(raw: Any) -> str:
    value = str(raw).strip().rstrip("/")
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError("an http:// or https:// URL with a host, like https://api.example.com/v1")
    return value


def identifier(raw: Any) -> str:
    value = str(raw).strip()
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._:@-]{0,127}", value):
        raise ValueError("1-128 characters of letters, digits and . _ : @ - (starting alnum)")
    return value


def bridge_input(raw: Any) -> str:
    value = str(raw).strip()
    if value in ("ros", "dds", "sim") or (value.startswith("bag:") and len(value) > 4):
        return value
    raise ValueError("ros, dds, sim or bag:PATH")


def existing_file(raw: Any) -> str:
    path = Path(str(raw)).expanduser()
    if not path.is_file():
        raise ValueError("the path of an existing file")
    return str(path)


def path_value(raw: Any) -> str:
    value = str(raw).strip()
    if not value:
        raise ValueError("a file path")
    return str(Path(value).expanduser())


def boolean(raw: Any) -> bool:
    if isinstance(raw, bool):
        return raw
    value = str(raw).strip().lower()
    if value in ("1", "true", "yes", "on"):
        return True
    if value in ("0", "false", "no", "off"):
        return False
    raise ValueError("true or false")


def _topic_list(raw: Any) -> list[str]:
    items = raw if isinstance(raw, list) else str(raw).split(",")
    return [str(item).strip() for item in items if str(item).strip()]


def topic_remap(raw: Any) -> dict[str, str]:
    """``/odom=/wheel/odom,/scan=/front/scan`` (or a TOML table) -> {topic: remapped}."""
    allowed = "topic=name pairs separated by commas, like /odom=/wheel/odom, for known topics"
    pairs = raw.items() if isinstance(raw, dict) else (p.split("=", 1) for p in _topic_list(raw))
    remap: dict[str, str] = {}
    for pair in pairs:
        if len(pair) != 2:
            raise ValueError(allowed)
        source, target = (str(part).strip() for part in pair)
        if source not in KNOWN_TOPICS or not target.startswith("/"):
            raise ValueError(allowed)
        remap[source] = target
    return remap


def topic_qos(raw: Any) -> dict[str, QosChoice]:
    """``/scan=best_effort,/goal_pose=reliable:transient_local`` -> per-topic QoS."""
    allowed = (
        "topic=reliability[:durability] pairs for known topics, reliability "
        "reliable or best_effort, durability volatile or transient_local"
    )
    pairs = raw.items() if isinstance(raw, dict) else (p.split("=", 1) for p in _topic_list(raw))
    choices = {}
    for pair in pairs:
        if len(pair) != 2:
            raise ValueError(allowed)
        topic, text = (str(part).strip() for part in pair)
        reliability, _, durability = text.partition(":")
        if (
            topic not in KNOWN_TOPICS
            or reliability not in ("reliable", "best_effort")
            or durability not in ("", "volatile", "transient_local")
        ):
            raise ValueError(allowed)
        choices[topic] = QosChoice(reliability == "reliable", durability == "transient_local")
    return choices


def namespace(raw: Any) -> str:
    value = str(raw).strip().rstrip("/")
    if not re.fullmatch(r"(/[A-Za-z][A-Za-z0-9_]*)+", value):
        raise ValueError("a ROS namespace like /robot1")
    return value


def topic_set(raw: Any) -> frozenset[str]:
    topics = _topic_list(raw)
    if any(topic not in KNOWN_TOPICS for topic in topics):
        raise ValueError("known topics separated by commas: " + ",".join(KNOWN_TOPICS))
    return frozenset(topics)


def secret(raw: Any) -> Secret:
    return raw if isinstance(raw, Secret) else Secret(str(raw).strip())


# ---------------------------------------------------------------- the settings


def setting(default: Any, parse: Callable[[Any], Any], doc: str, *aliases: str) -> Any:
    """Declare one setting: its default, its parser/validator, its doc line, env aliases."""
    return field(default=default, metadata={"parse": parse, "doc": doc, "aliases": aliases})


@dataclass(frozen=True)
class Settings:
    """The effective configuration, validated once at start."""

    phycloud_endpoint: str = setting(DEFAULT_ENDPOINT, http_url, "PhyCloud ingestion API base URL")
    phycloud_api_key: Secret = setting(Secret(""), secret, "API key sent as a Bearer token")
    source_id: str = setting("delivery-robot-001", identifier, "unique robot id", "ROBOT_ID")
    source_type: str = setting("delivery_robot", one_of(*SOURCE_TYPES), "robot class", "ROBOT_TYPE")
    fleet_id: str | None = setting(None, optional(identifier), "fleet grouping id")
    site_id: str | None = setting(None, optional(identifier), "site or facility id")
    sample_rate_hz: float = setting(
        DEFAULT_SAMPLE_RATE_HZ, positive_float(1000), "UDM events built per second"
    )
    batch_size: int = setting(DEFAULT_BATCH_SIZE, int_between(1, 10_000), "events per request")
    bridge_input: str = setting("ros", bridge_input, "where messages come from")
    use_sim_time: bool = setting(False, boolean, "header stamps follow /clock, not the epoch")
    replay_rate: float = setting(
        1.0, non_negative_float(1000), "bag replay speed: 1 = recorded, 0 = as fast as possible"
    )
    queue_path: str | None = setting(None, optional(path_value), "queue database file")
    queue_max_bytes: int = setting(
        DEFAULT_QUEUE_MAX_BYTES, byte_size(1 * MIB), "byte cap of the queue (WAL included)"
    )
    queue_max_events: int | None = setting(
        None, optional(int_between(1, 10**12)), "optional event cap of the queue"
    )
    queue_on_full: str = setting(
        "drop_oldest", one_of("drop_oldest", "drop_newest"), "what a full queue drops"
    )
    queue_ttl_s: float = setting(
        DEFAULT_QUEUE_TTL_S, positive_float(10 * 365 * 86400), "queued events expire after"
    )
    queue_compression: str = setting(
        "zstd", one_of("zstd", "gzip", "none"), "compression of queued events at rest"
    )
    queue_sync: str = setting("full", one_of("full", "normal"), "fsync policy of the queue")
    http_compression: str = setting(
        "gzip", one_of("gzip", "zstd", "none"), "Content-Encoding of requests"
    )
    batch_max_bytes: int = setting(
        DEFAULT_BATCH_MAX_BYTES, byte_size(1 * KIB), "byte bound of one request body"
    )
    flush_interval_s: float = setting(
        DEFAULT_FLUSH_INTERVAL_S, positive_float(3600), "send a partial batch after"
    )
    retry_min_s: float = setting(DEFAULT_RETRY_MIN_S, positive_float(3600), "first backoff")
    retry_max_s: float = setting(DEFAULT_RETRY_MAX_S, positive_float(86400), "longest backoff")
    http_timeout_s: float = setting(DEFAULT_HTTP_TIMEOUT_S, positive_float(600), "per request")
    shutdown_grace_s: float = setting(
        DEFAULT_SHUTDOWN_GRACE_S, positive_float(600), "time to flush at SIGTERM"
    )
    ca_bundle: str | None = setting(None, optional(existing_file), "extra CA file for TLS")
    upload_max_bps: int | None = setting(
        None, optional(int_between(1, 10**12)), "upload bandwidth cap, bytes/s"
    )
    stale_after_s: float = setting(
        DEFAULT_STALE_AFTER_S, positive_float(86400), "drop a domain whose data is older"
    )
    topic_remap: dict[str, str] = setting(
        None, optional(topic_remap), "topic renames, /odom=/wheel/odom,..."
    )
    topics_disabled: frozenset[str] = setting(
        frozenset(), topic_set, "topics not subscribed, /scan,..."
    )
    topic_namespace: str | None = setting(
        None, optional(namespace), "prefix of the topic names, e.g. /robot1"
    )
    topic_qos: dict[str, QosChoice] = setting(
        None, optional(topic_qos), "per-topic QoS instead of matching, /scan=best_effort,..."
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
    log_level: str = setting(
        "INFO",
        lambda raw: one_of("debug", "info", "warning", "error")(raw).upper(),
        "log threshold",
    )
    log_format: str = setting("text", one_of("text", "json"), "log line format")

    @property
    def topics(self) -> dict[str, str]:
        """Enabled topics: canonical name -> name subscribed on the robot (a remap wins
        over the namespace)."""
        remap = self.topic_remap or {}
        prefix = self.topic_namespace or ""
        return {t: remap.get(t, prefix + t) for t in KNOWN_TOPICS if t not in self.topics_disabled}


@dataclass(frozen=True)
class SettingInfo:
    """What the docs and ``phytrace-edge config`` say about one setting."""

    key: str
    env: str
    aliases: tuple[str, ...]
    flag: str
    default: Any
    doc: str
    parse: Callable[[Any], Any]


def setting_infos() -> list[SettingInfo]:
    """Every setting, in declaration order."""
    infos = []
    for f in fields(Settings):
        default = f.default if f.default is not MISSING else None
        infos.append(
            SettingInfo(
                key=f.name,
                env=f.name.upper(),
                aliases=f.metadata["aliases"],
                flag="--" + f.name.replace("_", "-"),
                default=default,
                doc=f.metadata["doc"],
                parse=f.metadata["parse"],
            )
        )
    return infos


@dataclass(frozen=True)
class LoadedSettings:
    """Settings plus where each value came from (``default``, ``env:NAME``, ...)."""

    settings: Settings
    origins: dict[str, str]


def _shown(info: SettingInfo, raw: Any) -> str:
    return "'***'" if info.key == "phycloud_api_key" else repr(raw)


def load_settings(
    flags: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
    config_file: Mapping[str, Any] | None = None,
    ros_params: Mapping[str, Any] | None = None,
    file_label: str = "file",
) -> LoadedSettings:
    """Resolve every setting from its sources (flags > env > file > ROS param > default).

    ``flags``, ``config_file`` and ``ros_params`` are keyed by the lower-case name; a
    flag whose value is None was not given. Raises ``ConfigError`` naming the setting,
    the value and what is allowed.
    """
    flags, env = flags or {}, env or {}
    config_file, ros_params = config_file or {}, ros_params or {}
    known = {info.key for info in setting_infos()}
    for key in config_file:
        if key not in known:
            raise ConfigError(f"{file_label}: unknown setting {key!r}")

    values: dict[str, Any] = {}
    origins: dict[str, str] = {}
    for info in setting_infos():
        raw, origin, name = _pick(info, flags, env, config_file, ros_params, file_label)
        if origin == "default":
            values[info.key] = info.default
        else:
            try:
                values[info.key] = info.parse(raw)
            except ValueError as exc:
                raise ConfigError(f"{name}={_shown(info, raw)}: must be {exc}") from None
        origins[info.key] = origin

    settings = Settings(**values)
    if settings.retry_max_s < settings.retry_min_s:
        raise ConfigError(
            f"RETRY_MAX_S={settings.retry_max_s:g}: must be >= RETRY_MIN_S "
            f"({settings.retry_min_s:g})"
        )
    if settings.queue_path is None:
        settings = replace(settings, queue_path=str(default_state_dir(env) / "queue.db"))
    return LoadedSettings(settings, origins)


def _pick(
    info: SettingInfo,
    flags: Mapping[str, Any],
    env: Mapping[str, str],
    config_file: Mapping[str, Any],
    ros_params: Mapping[str, Any],
    file_label: str,
) -> tuple[Any, str, str]:
    """The raw value of one setting, its origin label and the name to blame in errors."""
    if flags.get(info.key) is not None:
        return flags[info.key], f"flag {info.flag}", info.flag
    for name in (info.env, *info.aliases):
        if env.get(name, "").strip():
            return env[name], f"env {name}", name
    if info.key in config_file:
        return config_file[info.key], file_label, f"{file_label}: {info.key}"
    if info.key in ros_params:
        return ros_params[info.key], "ros param", f"ros param {info.key}"
    return None, "default", info.env


def read_config_file(path: str) -> dict[str, Any]:
    """Parse a TOML config file into a flat {key: value} table."""
    try:
        with Path(path).open("rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"config file {path}: not found") from None
    except OSError as exc:
        raise ConfigError(f"config file {path}: cannot read ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {path}: not valid TOML ({exc})") from None


def default_state_dir(env: Mapping[str, str]) -> Path:
    """Where the queue lives when QUEUE_PATH is not set.

    systemd's ``StateDirectory=`` sets ``$STATE_DIRECTORY`` (a colon-separated list);
    the container image sets ``PHYTRACE_STATE_DIR=/var/lib/phytrace-edge`` on its volume;
    otherwise the per-user XDG state directory.
    """
    if env.get("STATE_DIRECTORY"):
        return Path(env["STATE_DIRECTORY"].split(":")[0])
    if env.get("PHYTRACE_STATE_DIR"):
        return Path(env["PHYTRACE_STATE_DIR"])
    base = env.get("XDG_STATE_HOME") or str(Path(env.get("HOME", "~")) / ".local" / "state")
    return Path(base).expanduser() / "phytrace-edge"


def settings_from_environment(
    flags: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
    config_path: str | None = None,
    ros_params: Mapping[str, Any] | None = None,
) -> LoadedSettings:
    """Load settings the way the CLI does: flags, ``os.environ``, the config file named
    by ``--config`` or ``PHYTRACE_CONFIG``, and ROS parameters."""
    env = dict(os.environ) if env is None else env
    path = config_path or env.get("PHYTRACE_CONFIG") or None
    file_values = read_config_file(path) if path else {}
    return load_settings(flags, env, file_values, ros_params, file_label=f"config file {path}")


def ros_parameters(ros_args: list[str]) -> dict[str, str]:
    """``-p name:=value`` pairs of ROS arguments (as ``ros2 run`` and launch files pass
    them after ``--ros-args``); other ROS arguments (remaps, log levels) are rclpy's."""
    params = {}
    for flag, value in itertools.pairwise(ros_args):
        if flag in ("-p", "--param") and ":=" in value:
            name, _, text = value.partition(":=")
            text = text.strip().strip("'\"")
            if text:  # a launch argument left empty is not set
                params[name.strip()] = text
    return params
