"""Handlers of the status topics, where every message matters (diagnostics, delivery
status): ROS message -> reading, pure functions like those of ``handlers.py``."""

from __future__ import annotations

import json
import re
from typing import Any, cast

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import (
    add_repairs,
    checked_text,
    header_fields,
    integer,
    present,
    sequence_items,
)
from phytrace_edge.ingest.readings import (
    DeliveryStatusReading,
    DiagnosticsReading,
)
from phytrace_edge.ingest.safe_text import safe_bytes, safe_json, safe_str

DELIVERY_STATUS_MAX_BYTES = 64 * 1024
# a JSON escape of a surrogate (\ud800-\udfff): the text's own characters are repaired
# before parsing, so only these can put a lone surrogate into the parsed document
_SURROGATE_ESCAPE = re.compile(r"\\u[dD][89a-fA-F]")
# diagnostic_msgs/DiagnosticStatus.OK/WARN/ERROR/STALE
DIAGNOSTIC_LEVELS = {0: "ok", 1: "warn", 2: "error", 3: "stale"}


def _no_constants(name: str) -> Any:
    """NaN and Infinity are not JSON, whatever Python's parser allows."""
    raise ValueError(f"{name} is not JSON")


def handle_diagnostic_array(msg: Any) -> DiagnosticsReading:
    """``diagnostic_msgs/DiagnosticArray`` -> statuses with levels ok/warn/error/stale.

    The level is ``bytes`` (b'\\x02') in rclpy and ``int`` in rosbags and DDS; an
    unknown level value becomes ``unknown`` rather than being dropped.
    """
    statuses = []
    repaired = 0
    for status in sequence_items(msg, "status", 1024):
        level = integer(getattr(status, "level", None))
        name, name_repaired = checked_text(getattr(status, "name", None))
        message, message_repaired = checked_text(getattr(status, "message", None))
        hardware_id, hardware_repaired = checked_text(getattr(status, "hardware_id", None))
        repaired += name_repaired + message_repaired + hardware_repaired
        statuses.append(
            present(
                name=name or "(unnamed)",
                level=DIAGNOSTIC_LEVELS.get(level, "unknown") if level is not None else "unknown",
                message=message or None,
                hardware_id=hardware_id or None,
            )
        )
    reading = present(**header_fields(msg), statuses=statuses)
    add_repairs(reading, repaired)
    return cast(DiagnosticsReading, reading)


# /delivery/status JSON key -> (reading section, field)
_DELIVERY_FIELDS = {
    "order_id": ("payload", "order_id"),
    "package_id": ("payload", "package_id"),
    "state": ("payload", "delivery_state"),
    "destination": ("payload", "destination"),
    "task_id": ("task", "task_id"),
    "task_type": ("task", "task_type"),
    "task_status": ("task", "status"),
    "robot_state": ("operational", "state"),
}


def handle_delivery_status(msg: Any) -> DeliveryStatusReading:
    """``std_msgs/String`` holding a JSON object on /delivery/status -> task and payload.

    Raises ``MalformedMessage`` when the text is not a JSON object or is over 64 KiB.
    A field of the wrong type (or over 256 characters) is left out and listed in
    ``rejected_fields`` so the dispatcher can count it; the other fields still count.
    Text UTF-8 cannot carry (a lone surrogate, raw or escaped as ``"\\ud800"``, in a
    value or a key) is replaced by U+FFFD and counted in ``text_repaired``.
    """
    raw = getattr(msg, "data", None)
    if not isinstance(raw, (str, bytes)):
        raise MalformedMessage("not_text", f"data is {type(raw).__name__}, not a string")
    if len(raw) > DELIVERY_STATUS_MAX_BYTES:
        raise MalformedMessage("too_large", f"{len(raw)} bytes > {DELIVERY_STATUS_MAX_BYTES}")
    source, source_repaired = safe_bytes(raw) if isinstance(raw, bytes) else safe_str(raw)
    try:  # the standard library's parser: this module is on the start-up path of `config`
        document = json.loads(source, parse_constant=_no_constants)
    except (ValueError, RecursionError) as exc:
        raise MalformedMessage("bad_json", str(exc)[:120]) from None
    if not isinstance(document, dict):
        raise MalformedMessage("not_object", f"JSON {type(document).__name__}, not an object")
    repaired = int(source_repaired)
    if _SURROGATE_ESCAPE.search(source):  # what can still give a lone surrogate
        document, escaped = safe_json(document)
        repaired += escaped

    sections: dict[str, dict[str, str]] = {"payload": {}, "task": {}, "operational": {}}
    rejected = []
    for key, (section, name) in _DELIVERY_FIELDS.items():
        if key not in document or document[key] is None:
            continue
        value = _delivery_text(document[key])
        if value is None:
            rejected.append(key)
        else:
            sections[section][name] = value
    task, payload = sections["task"], sections["payload"]
    if "order_id" in payload:
        task.setdefault("task_id", payload["order_id"])
    if "package_id" in payload:
        task["payload_id"] = payload["package_id"]
    return cast(
        DeliveryStatusReading,
        present(
            task=task or None,
            payload=payload or None,
            state=sections["operational"].get("state"),
            rejected_fields=rejected or None,
            text_repaired=repaired or None,
        ),
    )


def _delivery_text(value: Any) -> str | None:
    """Ids and states are strings; integral ids are accepted as their decimal text."""
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or len(value) > 256:
        return None
    return value
