"""Value parsers of the settings: each takes the raw value (a string from the
environment or a flag, or a TOML or ROS parameter value) and returns the typed value,
or raises ValueError whose text says what is allowed.

Hostile values are expected: numbers are ASCII digits only (``int("٣")`` is 3 in
Python), whole numbers are never floats that get cut (``batch_size = 1.9``), sizes are
bounded before they are computed, and nothing here reads more than a little of a file.
"""

from __future__ import annotations

import math
import os
import re
import stat
from collections.abc import Callable
from typing import Any, TypeVar
from urllib.parse import urlsplit

from phytrace_edge.ingest.qos import QosChoice
from phytrace_edge.redact import Secret
from phytrace_edge.units import format_bytes

MAX_TEXT_CHARS = 4096  # no setting needs more; a longer value is a mistake
PEM_MARKER = b"-----BEGIN CERTIFICATE-----"
PEM_MAX_BYTES = 16 * 1024 * 1024
# Patterns as text, matched with ``_matches``: re compiles (and caches) one only when a
# setting that needs it is given, not at every start of every command.
_INTEGER = r"[+-]?[0-9]{1,30}"
_DECIMAL = r"[+-]?([0-9]{1,30}(\.[0-9]{0,30})?|\.[0-9]{1,30})([eE][+-]?[0-9]{1,3})?"
_SIZE = r"\s*([0-9]{1,20}(?:\.[0-9]{1,10})?)\s*([kmgtKMGT]?[iI]?[bB]?)\s*"
_HOST_LABEL = r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)"
_IDENTIFIER = r"[A-Za-z0-9][A-Za-z0-9._:@-]{0,127}"
_NAMESPACE = r"(/[A-Za-z][A-Za-z0-9_]*)+"
_TOPIC = r"(/[A-Za-z0-9_~{}]+)+"
_API_KEY = r"[\x21-\x7e]{1,4096}"  # printable ASCII, no spaces

T = TypeVar("T")


def _matches(pattern: str, text: str) -> re.Match[str] | None:
    """``pattern`` matched against all of ``text``, ASCII only (``\\d`` is not ``٣``)."""
    return re.fullmatch(pattern, text, re.ASCII)


def _text(raw: Any) -> str:
    """A value given as text (env, flag, ROS parameter) or a TOML string."""
    if not isinstance(raw, str):
        raise ValueError
    if len(raw) > MAX_TEXT_CHARS:
        raise ValueError
    return raw.strip()


def _text_or(raw: Any, allowed: str) -> str:
    """``_text``, failing with the setting's rule as the message."""
    try:
        return _text(raw)
    except ValueError:
        raise ValueError(allowed) from None


def _float(raw: Any) -> float:
    if isinstance(raw, bool):
        raise ValueError
    if isinstance(raw, (int, float)) or _matches(_DECIMAL, _text(raw)):
        value = float(raw)
    else:
        raise ValueError
    if not math.isfinite(value):
        raise ValueError
    return value


def _int(raw: Any) -> int:
    if isinstance(raw, (bool, float)):  # 1.9 must not become 1
        raise ValueError
    if isinstance(raw, int):
        return raw
    text = _text(raw)
    if not _matches(_INTEGER, text):
        raise ValueError
    return int(text)


def _bounded(
    convert: Callable[[Any], Any], lower: float, upper: float, allowed: str, open_low: bool
) -> Callable[[Any], Any]:
    def parse(raw: Any) -> Any:
        try:
            value = convert(raw)
        except ValueError:
            raise ValueError(allowed) from None
        if value > upper or value < lower or (open_low and value == lower):
            raise ValueError(allowed)
        return value

    return parse


def positive_float(upper: float) -> Callable[[Any], float]:
    return _bounded(_float, 0, upper, f"a number > 0 and <= {upper:g}", open_low=True)


def non_negative_float(upper: float) -> Callable[[Any], float]:
    return _bounded(_float, 0, upper, f"a number from 0 to {upper:g}", open_low=False)


def int_between(lower: int, upper: int) -> Callable[[Any], int]:
    return _bounded(_int, lower, upper, f"a whole number from {lower} to {upper}", open_low=False)


def optional(parse: Callable[[Any], T]) -> Callable[[Any], T | None]:
    def parse_optional(raw: Any) -> T | None:
        if raw is None or (isinstance(raw, str) and raw.strip().lower() in ("", "none")):
            return None
        try:
            return parse(raw)
        except ValueError as exc:
            raise ValueError(f"{exc} (or none)") from None

    return parse_optional


def one_of(*choices: str) -> Callable[[Any], str]:
    def parse(raw: Any) -> str:
        allowed = "one of " + ", ".join(choices)
        value = _text_or(raw, allowed).lower()
        if value not in choices:
            raise ValueError(allowed)
        return value

    return parse


def log_level(raw: Any) -> str:
    return one_of("debug", "info", "warning", "error")(raw).upper()


def byte_size(lower: int, upper: int = 2**50) -> Callable[[Any], int]:
    """Bytes as a number or with a unit: ``1048576``, ``512MiB``, ``1GiB``, ``1.5GB``."""

    def parse(raw: Any) -> int:
        allowed = (
            f"a size from {format_bytes(lower)} to {format_bytes(upper)}, "
            "like 1048576, 512MiB or 1GiB"
        )
        if isinstance(raw, int) and not isinstance(raw, bool):
            raw = str(raw)
        match = _matches(_SIZE, raw) if isinstance(raw, str) and len(raw) <= 64 else None
        if not match:
            raise ValueError(allowed)
        unit = match.group(2).lower()
        base = 1024 if "i" in unit else 1000
        scale = base ** "bkmgt".index(unit[0]) if unit and unit[0] != "b" else 1
        value = int(float(match.group(1)) * scale)
        if not lower <= value <= upper:
            raise ValueError(allowed)
        return value

    return parse


def http_url(raw: Any) -> str:
    """An http(s) URL with a valid host and port; the path is kept, a trailing / not."""
    allowed = "an http:// or https:// URL with a host, like https://api.example.com/v1"
    try:
        value = _text(raw).rstrip("/")
        parts = urlsplit(value)
        port = parts.port  # raises ValueError for a port that is not a number 0-65535
    except ValueError:
        raise ValueError(allowed) from None
    host = parts.hostname or ""
    if parts.scheme not in ("http", "https") or not _valid_host(host) or port == 0:
        raise ValueError(allowed)
    if any(c.isspace() or not c.isprintable() for c in value):
        raise ValueError(allowed)
    return value


def _valid_host(host: str) -> bool:
    if ":" in host:  # an IPv6 literal (urlsplit took the brackets away)
        import ipaddress  # here, not at the top: a millisecond of every command's start

        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            return False
        return True
    labels = host.rstrip(".").split(".")
    return bool(host) and all(_matches(_HOST_LABEL, label) for label in labels)


def identifier(raw: Any) -> str:
    allowed = "1-128 characters of letters, digits and . _ : @ - (starting alnum)"
    value = _text_or(raw, allowed)
    if not _matches(_IDENTIFIER, value):
        raise ValueError(allowed)
    return value


def bridge_input(raw: Any) -> str:
    allowed = "ros, dds, sim or bag:PATH"
    value = _text_or(raw, allowed)
    if value in ("ros", "dds", "sim") or (value.startswith("bag:") and len(value) > 4):
        return value
    raise ValueError(allowed)


def ca_file(raw: Any) -> str:
    """A PEM file of CA certificates: a readable regular file with a certificate in it
    (a wrong file fails here, not at the first TLS handshake)."""
    allowed = "the path of a readable PEM file of CA certificates"
    try:
        path = os.path.expanduser(_text(raw))
        if not stat.S_ISREG(os.stat(path).st_mode) or os.stat(path).st_size > PEM_MAX_BYTES:
            raise ValueError(allowed)
        with open(path, "rb") as handle:
            if PEM_MARKER not in handle.read(PEM_MAX_BYTES):
                raise ValueError(allowed)
    except (OSError, ValueError):
        raise ValueError(allowed) from None
    return path


def proxy_url(raw: Any) -> str:
    """``direct`` (no proxy, whatever the environment says), or an http(s) proxy URL;
    ``host:port`` means ``http://host:port``."""
    allowed = "a proxy URL like http://proxy.example.com:3128, or direct"
    value = _text_or(raw, allowed).strip()
    if value.lower() == "direct":
        return "direct"
    if "://" not in value:
        value = f"http://{value}"
    try:
        parts = urlsplit(value)
        parts.port  # noqa: B018 - a port that is not a number raises here
    except ValueError:
        raise ValueError(allowed) from None
    if parts.scheme not in ("http", "https") or not _valid_host(parts.hostname or ""):
        raise ValueError(allowed)
    return value


def path_value(raw: Any) -> str:
    allowed = "a file path"
    value = _text_or(raw, allowed)
    if not value or "\x00" in value:
        raise ValueError(allowed)
    return os.path.expanduser(value)


def boolean(raw: Any) -> bool:
    if isinstance(raw, bool):
        return raw
    allowed = "true or false"
    value = _text_or(raw, allowed).lower()
    if value in ("1", "true", "yes", "on"):
        return True
    if value in ("0", "false", "no", "off"):
        return False
    raise ValueError(allowed)


def _topic_list(raw: Any, allowed: str) -> list[str]:
    items = raw if isinstance(raw, list) else _text_or(raw, allowed).split(",")
    if not all(isinstance(item, str) for item in items):
        raise ValueError(allowed)
    return [item.strip() for item in items if item.strip()]


def _pairs(raw: Any, allowed: str) -> list[tuple[str, str]]:
    if isinstance(raw, dict):
        pairs = list(raw.items())
    else:
        pairs = [tuple(p.split("=", 1)) for p in _topic_list(raw, allowed)]  # type: ignore[misc]
    if not all(len(pair) == 2 and all(isinstance(x, str) for x in pair) for pair in pairs):
        raise ValueError(allowed)
    return [(a.strip(), b.strip()) for a, b in pairs]


def known_topics() -> tuple[str, ...]:
    """The topic table's names. Imported when a topic setting is given, not at every
    start: the table brings the handlers (1.5 ms of each command's start)."""
    from phytrace_edge.ingest.topics import TOPIC_NAMES

    return TOPIC_NAMES


def topic_remap(raw: Any) -> dict[str, str]:
    """``/odom=/wheel/odom,/scan=/front/scan`` (or a TOML table) -> {topic: remapped}."""
    allowed = "topic=name pairs separated by commas, like /odom=/wheel/odom, for known topics"
    remap = {}
    for source, target in _pairs(raw, allowed):
        if source not in known_topics() or not _matches(_TOPIC, target):
            raise ValueError(allowed)
        remap[source] = target
    return remap


def topic_qos(raw: Any) -> dict[str, QosChoice]:
    """``/scan=best_effort,/goal_pose=reliable:transient_local`` -> per-topic QoS."""
    allowed = (
        "topic=reliability[:durability] pairs for known topics, reliability "
        "reliable or best_effort, durability volatile or transient_local"
    )
    choices = {}
    for topic, text in _pairs(raw, allowed):
        reliability, _, durability = text.partition(":")
        if (
            topic not in known_topics()
            or reliability not in ("reliable", "best_effort")
            or durability not in ("", "volatile", "transient_local")
        ):
            raise ValueError(allowed)
        choices[topic] = QosChoice(reliability == "reliable", durability == "transient_local")
    return choices


def namespace(raw: Any) -> str:
    allowed = "a ROS namespace like /robot1"
    value = _text_or(raw, allowed).rstrip("/")
    if not _matches(_NAMESPACE, value):
        raise ValueError(allowed)
    return value


def topic_set(raw: Any) -> frozenset[str]:
    allowed = "known topics separated by commas: " + ",".join(known_topics())
    topics = _topic_list(raw, allowed)
    if any(topic not in known_topics() for topic in topics):
        raise ValueError(allowed)
    return frozenset(topics)


def topic_names(raw: Any) -> tuple[str, ...]:
    """Topic names separated by commas (the table's or TOPICS_EXTRA's: checked where
    both are known), in order, without repeats."""
    allowed = "topic names separated by commas, like /odom,/imu/data"
    topics = _topic_list(raw, allowed)
    if len(topics) > 64 or any(not _matches(_NAMESPACE, topic) for topic in topics):
        raise ValueError(allowed)
    return tuple(dict.fromkeys(topics))


def secret(raw: Any) -> Secret:
    """The API key: printable ASCII without spaces (a header value that cannot break
    the request, or leak through an error about a malformed header)."""
    if isinstance(raw, Secret):
        return raw
    allowed = "printable ASCII without spaces or control characters, at most 4096 characters"
    if not isinstance(raw, str) or len(raw) > MAX_TEXT_CHARS:
        raise ValueError(allowed)
    value = raw.strip("\r\n\t ")
    if value and not _matches(_API_KEY, value):
        raise ValueError(allowed)
    return Secret(value)
