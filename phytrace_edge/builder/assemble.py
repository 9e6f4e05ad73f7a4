"""Assemble one UDM event from the latest readings: a pure function of its inputs.

Domain rules (docs/udm.md has the field-by-field table):

- A domain appears only when a topic that feeds it has fresh data; absent topics mean
  absent domains, never invented nulls.
- Topics older than ``stale_after_s`` (measured from when the bridge received the
  message, on the monotonic clock, so it holds for any header clock) are left out;
  latched topics (goal, delivery status) stay and are reported with their age.
- Each domain lists its ``sources``: topic, age and the message's header stamp,
  classified as ``epoch``, ``sim`` (use_sim_time), ``non_epoch`` (a sensor clock that
  does not count from 1970, e.g. time since boot) or ``none`` (a zero stamp).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

from phytrace_edge.builder.envelope import classify_stamp, envelope
from phytrace_edge.ingest.convert import MM, compass_heading_deg, present, rounded
from phytrace_edge.ingest.readings import Reading, Readings
from phytrace_edge.ingest.topics import DOMAINS as DOMAINS  # an event's domains, re-exported
from phytrace_edge.ingest.topics import TOPIC_BY_NAME, TOPICS, Domain
from phytrace_edge.udm.types import PeriodicEvent, UdmIdentity

EVENT_TYPE_PERIODIC = "telemetry.periodic"
# The topics that feed each domain, in table order: the domain's ``sources``.
DOMAIN_TOPICS: dict[Domain, tuple[str, ...]] = {
    domain: tuple(spec.name for spec in TOPICS if domain in spec.domains) for domain in DOMAINS
}
MOVING_SPEED_MPS = 0.05
ROTATING_RATE_DPS = 2.0


@dataclass(frozen=True)
class Latest:
    """The newest reading of one topic and when the bridge received it."""

    reading: Reading
    received_mono_s: float


@dataclass
class Snapshot:
    """Everything one event is built from, taken atomically by the builder."""

    latest: dict[str, Latest]
    errors: list[dict[str, Any]] = field(default_factory=list)
    transitions: list[dict[str, Any]] = field(default_factory=list)
    new_goals: list[dict[str, Any]] = field(default_factory=list)


def is_fresh(topic: str, latest: Latest, now_mono_s: float, stale_after_s: float) -> bool:
    """Whether a topic's latest reading may be reported as current."""
    if TOPIC_BY_NAME[topic].latched:
        return True
    return now_mono_s - latest.received_mono_s <= stale_after_s


def assemble_event(
    identity: UdmIdentity,
    snapshot: Snapshot,
    *,
    event_id: str,
    captured_at_s: float,
    now_mono_s: float,
    stale_after_s: float,
    use_sim_time: bool = False,
) -> PeriodicEvent:
    """One ``telemetry.periodic`` event from ``snapshot`` (see the module doc)."""
    fresh = {
        topic: latest
        for topic, latest in snapshot.latest.items()
        if is_fresh(topic, latest, now_mono_s, stale_after_s)
    }
    readings = cast(Readings, {topic: latest.reading for topic, latest in fresh.items()})

    def sources(*topics: str) -> list[dict[str, Any]]:
        return [
            {
                "topic": topic,
                "age_s": round(max(0.0, now_mono_s - fresh[topic].received_mono_s), 3),
                **classify_stamp(fresh[topic].reading.get("stamp_ns"), captured_at_s, use_sim_time),
            }
            for topic in topics
            if topic in fresh
        ]

    event: PeriodicEvent = {**envelope(identity, EVENT_TYPE_PERIODIC, captured_at_s, event_id)}
    for name, build in DOMAIN_BUILDERS.items():
        domain = build(readings, snapshot)
        if domain:
            event[name] = {**domain, "sources": sources(*DOMAIN_TOPICS[name])}
    return event


def _location(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    gps = r.get("/gps/fix", {}).get("gps", {})
    orientation = r.get("/imu/data", {}).get("imu", {}).get("orientation_deg")
    located = "latitude" in gps
    return present(
        latitude=gps.get("latitude"),
        longitude=gps.get("longitude"),
        altitude_m=gps.get("altitude_m"),
        # A compass heading only makes sense with a geographic position; the IMU's
        # world frame is ENU (REP-103/REP-145), so its yaw converts directly.
        heading_deg=(compass_heading_deg(orientation["yaw"]) if located and orientation else None),
        coordinate_system="WGS84" if located else None,
        local=r.get("/odom", {}).get("local"),
    )


def _motion(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    odom = r.get("/odom", {})
    imu_rates = r.get("/imu/data", {}).get("imu", {}).get("angular_velocity_dps", {})
    linear = odom.get("linear_velocity")
    angular = odom.get("angular_velocity") or (
        {"yaw_dps": imu_rates["z"]} if "z" in imu_rates else None
    )
    speed = rounded(math.hypot(*linear.values()), MM) if linear else None
    return present(
        linear_velocity=linear,
        angular_velocity=angular,
        speed_mps=speed,
        commanded_velocity=r.get("/cmd_vel", {}).get("commanded_velocity"),
        motion_state=_motion_state(speed, (angular or {}).get("yaw_dps")),
    )


def _motion_state(speed: float | None, yaw_dps: float | None) -> str | None:
    if speed is None:
        return None
    if speed > MOVING_SPEED_MPS:
        return "moving"
    if yaw_dps is not None and abs(yaw_dps) > ROTATING_RATE_DPS:
        return "rotating"
    return "stationary"


def _power(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    battery = r.get("/battery_state")
    if battery is None:
        return {}
    return present(
        battery=battery.get("battery"),
        charging=battery.get("charging"),
        power_state=battery.get("power_state"),
    )


def _operational(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    delivery = r.get("/delivery/status", {})
    reporting_errors = "/diagnostics" in r or snapshot.errors
    return present(
        state=delivery.get("state"),
        task=delivery.get("task"),
        errors=snapshot.errors if reporting_errors else None,
        transitions=snapshot.transitions or None,
    )


def _navigation(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    return present(
        goal=r.get("/goal_pose", {}).get("goal"),
        new_goals=snapshot.new_goals or None,
    )


def _perception(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    lidar = r.get("/scan", {}).get("lidar")
    return present(
        lidar=[lidar] if lidar else None,
        imu=r.get("/imu/data", {}).get("imu"),
        gps=r.get("/gps/fix", {}).get("gps"),
    )


def _actuators(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    joints = r.get("/joint_states", {}).get("joints")
    return {"joints": joints} if joints else {}


def _payload(r: Readings, snapshot: Snapshot) -> dict[str, Any]:
    return r.get("/delivery/status", {}).get("payload") or {}


# How each domain is built from the readings, in the order of the event's keys.
DOMAIN_BUILDERS: dict[Domain, Callable[[Readings, Snapshot], dict[str, Any]]] = {
    "location": _location,
    "motion": _motion,
    "power": _power,
    "operational": _operational,
    "navigation": _navigation,
    "perception": _perception,
    "actuators": _actuators,
    "payload": _payload,
}
