"""Valid UDM events of every event type, for tests that carry events through a stage
without caring what they say (the hand-carry round trips)."""

from __future__ import annotations

from typing import Any

from phytrace_edge.builder.envelope import envelope
from phytrace_edge.udm.event import format_timestamp, format_timestamp_us, new_event_id

EVENT_TYPES = ("telemetry.periodic", "telemetry.topic", "log.record", "bridge.health", "incident")


def udm_event(event_type: str, identity: dict[str, str], at_s: float, n: int) -> dict[str, Any]:
    """One valid event of ``event_type`` captured at ``at_s``; ``n`` varies its body."""
    event = envelope(identity, event_type, at_s)
    if event_type == "telemetry.periodic":
        body: dict[str, Any] = {"power": {"battery": {"voltage_v": 24.0 + (n % 10) / 10}}}
    elif event_type == "telemetry.topic":
        body = {
            "topic": "/motor/temperature",
            "type": "sensor_msgs/msg/Temperature",
            "mode": "sample",
            "data": {"temperature": 40.0 + n % 7, "variance": 0.0},
            "age_s": 0.1,
            "clock": "epoch",
        }
    elif event_type == "log.record":
        body = {
            "level": "warn",
            "logger": "nav2.controller",
            "message": f"slow loop {n}",
            "clock": "epoch",
        }
    elif event_type == "incident":
        at = format_timestamp(at_s)
        body = {
            "incident": {
                "id": new_event_id(int(at_s * 1000)),
                "part": 1,
                "parts": 1,
                "trigger": {"kind": "manual", "message": f"mark {n}", "at": at},
                "window": {"start": at, "end": at},
                "samples": {
                    "/odom": [
                        {"t": format_timestamp_us(at_s), "linear_velocity": {"x_mps": n / 10}}
                    ]
                },
            }
        }
    else:
        body = {
            "trigger": "interval",
            "healthy": True,
            "problems": [],
            "version": "0.2.0",
            "uptime_s": float(n),
            "queue": {"depth": n, "bytes": 4096},
        }
    return {**event, **body}


def every_type(
    count: int, identity: dict[str, str], start_s: float, step_s: float = 0.2
) -> list[dict[str, Any]]:
    """``count`` events, the five types in turn, ``step_s`` apart."""
    return [
        udm_event(EVENT_TYPES[i % len(EVENT_TYPES)], identity, start_s + i * step_s, i)
        for i in range(count)
    ]
