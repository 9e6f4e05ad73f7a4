"""Handlers of the status topics, where every message matters (diagnostics, delivery
status): ROS message -> reading, pure functions like those of ``handlers.py``."""

from __future__ import annotations

import json
from typing import Any, cast

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import header_fields, integer, present, sequence_items, text
from phytrace_edge.ingest.readings import (
    DeliveryStatusReading,
    DiagnosticsReading,
)

DELIVERY_STATUS_MAX_BYTES = 64 * 1024
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
    for status in sequence_items(msg, "status", 1024):
        level = integer(getattr(status, "level", None))
        name = text(getattr(status, "name", None)) or "(unnamed)"
        statuses.append(
            present(
                name=name,
                level=DIAGNOSTIC_LEVELS.get(level, "unknown") if level is not None else "unknown",
                message=text(getattr(status, "message", None)) or None,
                hardware_id=text(getattr(status, "hardware_id", None)) or None,
            )
        )
    return cast(DiagnosticsReading, present(**header_fields(msg), statuses=statuses))


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
    """
    raw = getattr(msg, "data", None)
    if not isinstance(raw, (str, bytes)):
        raise MalformedMessage("not_text", f"data is {type(raw).__name__}, not a string")
    if len(raw) > DELIVERY_STATUS_MAX_BYTES:
        raise MalformedMessage("too_large", f"{len(raw)} bytes > {DELIVERY_STATUS_MAX_BYTES}")
    try:  # the standard library's parser: this module is on the start-up path of `config`
        document = json.loads(raw, parse_constant=_no_constants)
    except (ValueError, RecursionError) as exc:
        raise MalformedMessage("bad_json", str(exc)[:120]) from None
    if not isinstance(document, dict):
        raise MalformedMessage("not_object", f"JSON {type(document).__name__}, not an object")

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
        ),
    )


def _delivery_text(value: Any) -> str | None:
    """Ids and states are strings; integral ids are accepted as their decimal text."""
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or len(value) > 256:
        return None
    return value
