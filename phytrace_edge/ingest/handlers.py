"""Topic handlers: one pure function per topic, ROS message -> reading (a plain dict).

Handlers read attributes only, so the same function accepts an rclpy message, a
rosbags message, a Cyclone DDS IDL sample or the mock. Readings are already in UDM
units and shapes (see docs/udm.md); fields that are unset, NaN or infinite are left out.
Each reading may carry ``stamp_ns`` (the header stamp) and ``frame_id``; the builder
turns those into the domain's ``sources`` entry.

A message that cannot be read at all raises ``MalformedMessage``; any other exception
from a handler is a bug the dispatcher counts as ``handler_error``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import orjson

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import (
    compact,
    degrees,
    finite,
    first_number,
    header_fields,
    integer,
    pose_fields,
    quaternion_to_rpy_deg,
    sequence_items,
    text,
    wrap_degrees,
    xyz,
    xyz_deg,
)

Reading = dict[str, Any]

DELIVERY_STATUS_MAX_BYTES = 64 * 1024
MAX_JOINTS = 256
MAX_CELLS = 256
PERCENTAGE_SLACK = 1e-3  # float32 rounding of 0.0 and 1.0

# sensor_msgs/BatteryState.POWER_SUPPLY_STATUS_*
_SUPPLY_STATUS = {1: "charging", 2: "discharging", 3: "not_charging", 4: "full"}
_POWER_STATE = {1: "charging", 2: "on_battery", 3: "on_battery", 4: "full"}
# sensor_msgs/BatteryState.POWER_SUPPLY_HEALTH_* (0 = unknown: left out)
_HEALTH = {
    1: "good",
    2: "overheat",
    3: "dead",
    4: "overvoltage",
    5: "unspec_failure",
    6: "cold",
    7: "watchdog_timer_expire",
    8: "safety_timer_expire",
}
# diagnostic_msgs/DiagnosticStatus.OK/WARN/ERROR/STALE
DIAGNOSTIC_LEVELS = {0: "ok", 1: "warn", 2: "error", 3: "stale"}
# sensor_msgs/NavSatStatus.STATUS_* (-2 STATUS_UNKNOWN exists since Jazzy)
_NO_FIX, _FIX, _SBAS_FIX, _GBAS_FIX = -1, 0, 1, 2
# sensor_msgs/NavSatFix.COVARIANCE_TYPE_UNKNOWN
_COVARIANCE_UNKNOWN = 0


def handle_odometry(msg: Any) -> Reading:
    """``nav_msgs/Odometry`` -> local pose (location) and body velocity (motion).

    The pose is in ``header.frame_id`` (odom or map), the twist in ``child_frame_id``
    (the robot body, x forward, y left: REP-103).
    """
    head = header_fields(msg)
    twist = getattr(getattr(msg, "twist", None), "twist", None)
    angular = getattr(twist, "angular", None)
    pose = pose_fields(getattr(getattr(msg, "pose", None), "pose", None))
    return compact(
        {
            **head,
            "local": {"coordinate_frame": head["frame_id"], **pose},
            "linear_velocity": xyz(getattr(twist, "linear", None), ("x_mps", "y_mps", "z_mps")),
            "angular_velocity": {
                "roll_dps": degrees(getattr(angular, "x", None)),
                "pitch_dps": degrees(getattr(angular, "y", None)),
                "yaw_dps": degrees(getattr(angular, "z", None)),
            },
        }
    )


def handle_battery_state(msg: Any) -> Reading:
    """``sensor_msgs/BatteryState`` -> power domain.

    ``percentage`` is 0..1 in ROS and becomes ``state_of_charge_pct`` 0..100; a value
    outside 0..1 (a driver publishing percent, say) is left out and reported in
    ``rejected_fields`` rather than guessed at. Fields a battery does not measure are
    NaN by ROS convention and are left out.
    """
    percentage = finite(getattr(msg, "percentage", None))
    in_range = percentage is not None and -PERCENTAGE_SLACK <= percentage <= 1 + PERCENTAGE_SLACK
    soc = min(100.0, max(0.0, percentage * 100.0)) if in_range else None  # type: ignore[operator]
    status = integer(getattr(msg, "power_supply_status", None))
    present = getattr(msg, "present", None)
    cells = [finite(v) for v in sequence_items(msg, "cell_voltage", MAX_CELLS)]
    return compact(
        {
            **header_fields(msg),
            "battery": {
                "voltage_v": finite(getattr(msg, "voltage", None)),
                "current_a": finite(getattr(msg, "current", None)),
                "state_of_charge_pct": soc,
                "temperature_c": finite(getattr(msg, "temperature", None)),
                "charge_ah": finite(getattr(msg, "charge", None)),
                "capacity_ah": finite(getattr(msg, "capacity", None)),
                "health": _HEALTH.get(integer(getattr(msg, "power_supply_health", None)) or 0),
                "present": present if isinstance(present, bool) else None,
                "cell_voltages_v": [v for v in cells if v is not None] or None,
            },
            "charging": (
                {"is_charging": status == 1, "status": _SUPPLY_STATUS[status]}
                if status in _SUPPLY_STATUS
                else None
            ),
            "power_state": _POWER_STATE.get(status or 0, "unknown"),
            "rejected_fields": ["percentage"] if percentage is not None and not in_range else None,
        }
    )


def handle_laser_scan(msg: Any) -> Reading:
    """``sensor_msgs/LaserScan`` -> one lidar entry of the perception domain.

    ``min_range_m``/``max_range_m``/``num_points`` are the sensor's ``range_min``,
    ``range_max`` and beam count. A return is valid when it is finite and within
    [range_min, range_max]; ``closest_range_m`` is the nearest valid return and
    ``closest_bearing_deg`` its angle in the scan frame.
    """
    try:
        ranges = np.asarray(getattr(msg, "ranges", ()), dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise MalformedMessage("bad_ranges", f"ranges is not a numeric array ({exc})") from None
    range_min = finite(getattr(msg, "range_min", None))
    range_max = finite(getattr(msg, "range_max", None))
    if range_min is not None and range_max is not None and 0 <= range_min <= range_max:
        bounds_ok, low, high = True, range_min, range_max
    else:  # broken bounds: any finite positive value counts as a return
        bounds_ok, low, high = False, math.ulp(0.0), math.inf
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= low) & (ranges <= high)
    valid_count = int(valid.sum())
    closest = bearing = None
    if valid_count:
        index = int(np.argmin(np.where(valid, ranges, np.inf)))
        closest = float(ranges[index])
        angle_min = finite(getattr(msg, "angle_min", None))
        increment = finite(getattr(msg, "angle_increment", None))
        if angle_min is not None and increment is not None:
            angle = finite(math.degrees(angle_min + index * increment))
            bearing = None if angle is None else wrap_degrees(angle)
    head = header_fields(msg)
    return compact(
        {
            **head,
            "lidar": {
                "sensor_id": head["frame_id"] or "laser",
                "min_range_m": range_min if bounds_ok else None,
                "max_range_m": range_max if bounds_ok else None,
                "num_points": int(ranges.size),
                "valid_points": valid_count,
                "closest_range_m": closest,
                "closest_bearing_deg": bearing,
                "angle_min_deg": degrees(getattr(msg, "angle_min", None)),
                "angle_max_deg": degrees(getattr(msg, "angle_max", None)),
            },
        }
    )


def handle_imu(msg: Any) -> Reading:
    """``sensor_msgs/Imu`` -> perception.imu (and motion's yaw rate when odom is absent).

    By REP-145 an ``orientation_covariance[0]`` of -1 means the IMU gives no
    orientation; it is then left out.
    """
    no_orientation = first_number(getattr(msg, "orientation_covariance", None)) == -1
    rpy = None if no_orientation else quaternion_to_rpy_deg(getattr(msg, "orientation", None))
    return compact(
        {
            **header_fields(msg),
            "imu": {
                "orientation_deg": (
                    {"roll": rpy[0], "pitch": rpy[1], "yaw": rpy[2]} if rpy else None
                ),
                "angular_velocity_dps": xyz_deg(getattr(msg, "angular_velocity", None)),
                "linear_acceleration_mps2": xyz(getattr(msg, "linear_acceleration", None)),
            },
        }
    )


def handle_twist(msg: Any) -> Reading:
    """``geometry_msgs/Twist`` (or ``TwistStamped``) on /cmd_vel -> commanded velocity.

    ``angular_z_rps`` is in rad/s, as the reference event names it.
    """
    twist = getattr(msg, "twist", msg)
    linear = getattr(twist, "linear", None)
    head = header_fields(msg) if hasattr(msg, "header") else {}
    return compact(
        {
            **head,
            "commanded_velocity": {
                "linear_x_mps": finite(getattr(linear, "x", None)),
                "linear_y_mps": finite(getattr(linear, "y", None)),
                "angular_z_rps": finite(getattr(getattr(twist, "angular", None), "z", None)),
            },
        }
    )


def handle_nav_sat_fix(msg: Any) -> Reading:
    """``sensor_msgs/NavSatFix`` -> perception.gps and location's WGS84 position.

    ``status.status`` -1 no fix, 0 fix (3D when altitude is known, else 2D), 1 SBAS,
    2 GBAS; Jazzy's -2 is unknown. Without a fix the coordinates are meaningless and
    are left out. NavSatFix carries no satellite count, so none is reported.
    """
    status = integer(getattr(getattr(msg, "status", None), "status", None))
    latitude = finite(getattr(msg, "latitude", None))
    longitude = finite(getattr(msg, "longitude", None))
    altitude = finite(getattr(msg, "altitude", None))
    if latitude is not None and not -90 <= latitude <= 90:
        latitude = None
    if longitude is not None and not -180 <= longitude <= 180:
        longitude = None
    fix_type = _fix_type(status, altitude)
    has_fix = fix_type not in ("no_fix", "unknown") and latitude is not None
    gps: dict[str, Any] = {"fix_type": fix_type}
    if has_fix and longitude is not None:
        gps.update(latitude=latitude, longitude=longitude, altitude_m=altitude)
        gps["horizontal_accuracy_m"] = _horizontal_accuracy(msg)
    return compact({**header_fields(msg), "gps": gps})


def _fix_type(status: int | None, altitude: float | None) -> str:
    if status == _NO_FIX:
        return "no_fix"
    if status == _FIX:
        return "3d_fix" if altitude is not None else "2d_fix"
    if status == _SBAS_FIX:
        return "sbas_fix"
    if status == _GBAS_FIX:
        return "gbas_fix"
    return "unknown"


def _horizontal_accuracy(msg: Any) -> float | None:
    """1-sigma horizontal error in metres from the ENU position covariance."""
    if integer(getattr(msg, "position_covariance_type", None)) in (None, _COVARIANCE_UNKNOWN):
        return None
    covariance = list(sequence_items(msg, "position_covariance", 9))
    if len(covariance) < 5:
        return None
    east, north = finite(covariance[0]), finite(covariance[4])
    if east is None or north is None or east < 0 or north < 0:
        return None
    return math.sqrt(max(east, north))


def handle_diagnostic_array(msg: Any) -> Reading:
    """``diagnostic_msgs/DiagnosticArray`` -> statuses with levels ok/warn/error/stale.

    The level is ``bytes`` (b'\\x02') in rclpy and ``int`` in rosbags and DDS; an
    unknown level value becomes ``unknown`` rather than being dropped.
    """
    statuses = []
    for status in sequence_items(msg, "status", 1024):
        level = integer(getattr(status, "level", None))
        name = text(getattr(status, "name", None)) or "(unnamed)"
        statuses.append(
            compact(
                {
                    "name": name,
                    "level": DIAGNOSTIC_LEVELS.get(level, "unknown")
                    if level is not None
                    else "unknown",
                    "message": text(getattr(status, "message", None)) or None,
                    "hardware_id": text(getattr(status, "hardware_id", None)) or None,
                }
            )
        )
    return compact({**header_fields(msg), "statuses": statuses})


def handle_pose_stamped(msg: Any) -> Reading:
    """``geometry_msgs/PoseStamped`` on /goal_pose -> navigation goal."""
    head = header_fields(msg)
    pose = pose_fields(getattr(msg, "pose", None))
    return compact({**head, "goal": {"frame_id": head["frame_id"], **pose}})


def handle_joint_state(msg: Any) -> Reading:
    """``sensor_msgs/JointState`` -> actuators.joints.

    position is rad (or m for prismatic joints), velocity rad/s, effort N·m (or N).
    ROS allows the value arrays to be empty or shorter than ``name``.
    """
    names = list(sequence_items(msg, "name", MAX_JOINTS))
    values = {
        "position_rad": list(sequence_items(msg, "position", MAX_JOINTS)),
        "velocity_rps": list(sequence_items(msg, "velocity", MAX_JOINTS)),
        "effort": list(sequence_items(msg, "effort", MAX_JOINTS)),
    }
    joints = []
    for index, name in enumerate(names):
        joint: dict[str, Any] = {"name": text(name) or f"joint_{index}"}
        for key, column in values.items():
            joint[key] = finite(column[index]) if index < len(column) else None
        joints.append(compact(joint))
    return compact({**header_fields(msg), "joints": joints})


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


def handle_delivery_status(msg: Any) -> Reading:
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
    try:
        document = orjson.loads(raw)
    except orjson.JSONDecodeError as exc:
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
    return compact(
        {
            "task": task or None,
            "payload": payload or None,
            "state": sections["operational"].get("state"),
            "rejected_fields": rejected or None,
        }
    )


def _delivery_text(value: Any) -> str | None:
    """Ids and states are strings; integral ids are accepted as their decimal text."""
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or len(value) > 256:
        return None
    return value
