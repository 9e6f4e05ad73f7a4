"""The parser of ``TOPICS_EXTRA``: any other topic, as a TOML table per topic or as
text (``/motor/temp type=sensor_msgs/msg/Temperature mode=on_change deadband=0.5;
/tf rate_hz=10``). Stdlib only, like every parser on the start-up path."""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the topic table is imported when TOPICS_EXTRA is given (parsers.py)
    from phytrace_edge.ingest.topics import ExtraTopic

MAX_EXTRA_TOPICS = 64
MAX_RATE_HZ = 1000.0
ALLOWED = (
    "topics outside the table, each with optional type=pkg/msg/Name, rate_hz (0 < r "
    "<= 1000), mode=sample or on_change, deadband (>= 0, on_change only): as TOML "
    "tables or as text like '/motor/temp mode=on_change deadband=0.5; /tf rate_hz=10'"
)
_TOPIC = r"(/[A-Za-z0-9_~{}]+)+"
_TYPE = r"[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*"
_NUMBER = r"[0-9]{1,9}(\.[0-9]{1,9})?"


def topics_extra(raw: Any) -> tuple[ExtraTopic, ...]:
    """TOPICS_EXTRA -> its entries; ValueError(ALLOWED) for anything else."""
    if isinstance(raw, dict):
        entries = list(raw.items())
    elif isinstance(raw, str) and len(raw) <= 16 * 1024:
        entries = [_text_entry(part) for part in raw.split(";") if part.strip()]
    else:
        raise ValueError(ALLOWED)
    if len(entries) > MAX_EXTRA_TOPICS or len({name for name, _ in entries}) < len(entries):
        raise ValueError(ALLOWED)
    return tuple(_entry(name, options) for name, options in entries)


def _text_entry(part: str) -> tuple[str, dict[str, Any]]:
    name, *pairs = part.split()
    options: dict[str, Any] = {}
    for pair in pairs:
        key, equals, value = pair.partition("=")
        if not equals or key in options:
            raise ValueError(ALLOWED)
        options[key] = value
    return name, options


def _entry(name: Any, options: Any) -> ExtraTopic:
    from phytrace_edge.ingest.topics import EXTRA_MODES, TOPIC_NAMES, ExtraTopic

    if (
        not isinstance(name, str)
        or not re.fullmatch(_TOPIC, name, re.ASCII)
        or name in TOPIC_NAMES
        or not isinstance(options, dict)
        or set(options) - {"type", "rate_hz", "mode", "deadband"}
    ):
        raise ValueError(ALLOWED)
    type_name = options.get("type", "")
    mode = options.get("mode", "sample")
    if not isinstance(type_name, str) or (type_name and not re.fullmatch(_TYPE, type_name)):
        raise ValueError(ALLOWED)
    if mode not in EXTRA_MODES or ("deadband" in options and mode != "on_change"):
        raise ValueError(ALLOWED)
    mode = EXTRA_MODES[EXTRA_MODES.index(mode)]  # the checked text, as a TopicMode
    rate_hz = _number(options.get("rate_hz", 1.0))
    deadband = _number(options.get("deadband", 0.0))
    if not 0 < rate_hz <= MAX_RATE_HZ:
        raise ValueError(ALLOWED)
    return ExtraTopic(name, type_name, rate_hz, mode, deadband)


def _number(raw: Any) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float, str)):
        raise ValueError(ALLOWED)
    if isinstance(raw, str) and not re.fullmatch(_NUMBER, raw, re.ASCII):
        raise ValueError(ALLOWED)
    value = float(raw)
    if not math.isfinite(value) or value < 0:
        raise ValueError(ALLOWED)
    return value
