"""Value parsers of the settings: each takes the raw value (a string from the
environment or a flag, or a TOML or ROS parameter value) and returns the typed value,
or raises ValueError whose text says what is allowed."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from phytrace_edge.ingest.qos import QosChoice
from phytrace_edge.ingest.topics import TOPIC_NAMES
from phytrace_edge.redact import Secret
from phytrace_edge.units import format_bytes

KNOWN_TOPICS = TOPIC_NAMES


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
