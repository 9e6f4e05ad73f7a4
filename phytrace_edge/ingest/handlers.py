"""Handlers of the state topics: one pure function per topic, ROS message -> reading
(a plain dict). The status topics (diagnostics, delivery status) are in ``status.py``.

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
from typing import Any, cast

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import (
    LATLON,
    MILLIDEGREE,
    MM,
    PERCENT,
    RAD,
    RAD_S,
    add_repairs,
    checked_text,
    degrees,
    f32,
    f32_all,
    finite,
    first_number,
    float_array,
    header_fields,
    integer,
    pose_fields,
    present,
    quaternion_to_rpy_deg,
    rounded,
    sequence_items,
    single,
    snap,
    wrap_degrees,
    xyz,
    xyz_deg,
)
from phytrace_edge.ingest.readings import (
    BatteryReading,
    GoalReading,
    ImuReading,
    JointStateReading,
    LaserScanReading,
    NavSatFixReading,
    OdometryReading,
    TwistReading,
)

_VELOCITY_KEYS = ("x_mps", "y_mps", "z_mps")
_RATE_KEYS = ("roll_dps", "pitch_dps", "yaw_dps")
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
# sensor_msgs/NavSatStatus.STATUS_* (-2 STATUS_UNKNOWN exists since Jazzy)
_NO_FIX, _FIX, _SBAS_FIX, _GBAS_FIX = -1, 0, 1, 2
# sensor_msgs/NavSatFix.COVARIANCE_TYPE_UNKNOWN
_COVARIANCE_UNKNOWN = 0


def handle_odometry(msg: Any) -> OdometryReading:
    """``nav_msgs/Odometry`` -> local pose (location) and body velocity (motion).

    The pose is in ``header.frame_id`` (odom or map), the twist in ``child_frame_id``
    (the robot body, x forward, y left: REP-103).
    """
    reading = cast(OdometryReading, header_fields(msg))
    twist = getattr(getattr(msg, "twist", None), "twist", None)
    local = pose_fields(getattr(getattr(msg, "pose", None), "pose", None))
    if "frame_id" in reading:
        local["coordinate_frame"] = reading["frame_id"]
    if local:
        reading["local"] = local
    linear = xyz(getattr(twist, "linear", None), _VELOCITY_KEYS)
    if linear:
        reading["linear_velocity"] = linear
    angular = xyz_deg(getattr(twist, "angular", None), _RATE_KEYS)
    if angular:
        reading["angular_velocity"] = angular
    return reading


def handle_battery_state(msg: Any) -> BatteryReading:
    """``sensor_msgs/BatteryState`` -> power domain.

    ``percentage`` is 0..1 in ROS and becomes ``state_of_charge_pct`` 0..100; a value
    outside 0..1 (a driver publishing percent, say) is left out and reported in
    ``rejected_fields`` rather than guessed at. Fields a battery does not measure are
    NaN by ROS convention and are left out.
    """
    percentage = finite(getattr(msg, "percentage", None))
    in_range = percentage is not None and -PERCENTAGE_SLACK <= percentage <= 1 + PERCENTAGE_SLACK
    status = integer(getattr(msg, "power_supply_status", None))
    is_present = getattr(msg, "present", None)
    # every float field of BatteryState is float32: all at their real precision at once
    try:
        voltage, current, temperature, charge, capacity, *cells = f32_all(
            [
                getattr(msg, "voltage", None),
                getattr(msg, "current", None),
                getattr(msg, "temperature", None),
                getattr(msg, "charge", None),
                getattr(msg, "capacity", None),
            ],
            sequence_items(msg, "cell_voltage", MAX_CELLS),
        )
    except (TypeError, ValueError) as exc:
        raise MalformedMessage("bad_sequence", f"cell_voltage is not numeric ({exc})") from None
    reading = cast(BatteryReading, header_fields(msg))
    reading["battery"] = present(
        voltage_v=voltage,
        current_a=current,
        state_of_charge_pct=(
            rounded(min(100.0, max(0.0, percentage * 100.0)), PERCENT)  # type: ignore[operator]
            if in_range
            else None
        ),
        temperature_c=temperature,
        charge_ah=charge,
        capacity_ah=capacity,
        health=_HEALTH.get(integer(getattr(msg, "power_supply_health", None)) or 0),
        present=is_present if isinstance(is_present, bool) else None,
        cell_voltages_v=[v for v in cells if v is not None] or None,
    )
    if status in _SUPPLY_STATUS:
        reading["charging"] = {"is_charging": status == 1, "status": _SUPPLY_STATUS[status]}
    reading["power_state"] = _POWER_STATE.get(status or 0, "unknown")
    if percentage is not None and not in_range:
        reading["rejected_fields"] = ["percentage"]
    if not reading["battery"]:
        del reading["battery"]
    return reading


def handle_laser_scan(msg: Any) -> LaserScanReading:
    """``sensor_msgs/LaserScan`` -> one lidar entry of the perception domain.

    ``min_range_m``/``max_range_m``/``num_points`` are the sensor's ``range_min``,
    ``range_max`` and beam count. A return is valid when it is finite and within
    [range_min, range_max]; ``closest_range_m`` is the nearest valid return and
    ``closest_bearing_deg`` its angle in the scan frame.
    """
    try:
        ranges = float_array(getattr(msg, "ranges", ()))
    except (TypeError, ValueError) as exc:
        raise MalformedMessage("bad_ranges", f"ranges is not a numeric array ({exc})") from None
    range_min = f32(getattr(msg, "range_min", None))
    range_max = f32(getattr(msg, "range_max", None))
    if range_min is not None and range_max is not None and 0 <= range_min <= range_max:
        # compared as float32, the type of the bounds and of the ranges alike
        bounds_ok, low, high = True, single(range_min), single(range_max)
        valid = [r for r in ranges if low <= r <= high]  # NaN compares False: left out
    else:  # broken bounds: any finite positive value counts as a return
        bounds_ok = False
        valid = [r for r in ranges if 0 < r < math.inf]
    closest = bearing = None
    if valid:
        nearest = min(valid)
        index = ranges.index(nearest)  # every item equal to a valid one is valid
        closest = f32(nearest)
        angle_min = finite(getattr(msg, "angle_min", None))
        increment = finite(getattr(msg, "angle_increment", None))
        if angle_min is not None and increment is not None:
            angle = finite(math.degrees(angle_min + index * increment))
            bearing = None if angle is None else snap(wrap_degrees(angle), MILLIDEGREE)
    head = header_fields(msg)
    return cast(
        LaserScanReading,
        present(
            **head,
            lidar=present(
                sensor_id=head.get("frame_id") or "laser",
                min_range_m=range_min if bounds_ok else None,
                max_range_m=range_max if bounds_ok else None,
                num_points=len(ranges),
                valid_points=len(valid),
                closest_range_m=closest,
                closest_bearing_deg=bearing,
                angle_min_deg=degrees(getattr(msg, "angle_min", None)),
                angle_max_deg=degrees(getattr(msg, "angle_max", None)),
            ),
        ),
    )


def handle_imu(msg: Any) -> ImuReading:
    """``sensor_msgs/Imu`` -> perception.imu (and motion's yaw rate when odom is absent).

    By REP-145 an ``orientation_covariance[0]`` of -1 means the IMU gives no
    orientation; it is then left out.
    """
    no_orientation = first_number(getattr(msg, "orientation_covariance", None)) == -1
    rpy = None if no_orientation else quaternion_to_rpy_deg(getattr(msg, "orientation", None))
    return cast(
        ImuReading,
        present(
            **header_fields(msg),
            imu=present(
                orientation_deg={"roll": rpy[0], "pitch": rpy[1], "yaw": rpy[2]} if rpy else None,
                angular_velocity_dps=xyz_deg(getattr(msg, "angular_velocity", None)),
                linear_acceleration_mps2=xyz(getattr(msg, "linear_acceleration", None)),
            ),
        ),
    )


def handle_twist(msg: Any) -> TwistReading:
    """``geometry_msgs/Twist`` (or ``TwistStamped``) on /cmd_vel -> commanded velocity.

    ``angular_z_rps`` is in rad/s, as the reference event names it
    (tests/data/reference_event.json).
    """
    twist = getattr(msg, "twist", msg)
    linear = getattr(twist, "linear", None)
    head = header_fields(msg) if hasattr(msg, "header") else {}
    return cast(
        TwistReading,
        present(
            **head,
            commanded_velocity=present(
                linear_x_mps=rounded(getattr(linear, "x", None), MM),
                linear_y_mps=rounded(getattr(linear, "y", None), MM),
                angular_z_rps=rounded(getattr(getattr(twist, "angular", None), "z", None), RAD_S),
            ),
        ),
    )


def handle_nav_sat_fix(msg: Any) -> NavSatFixReading:
    """``sensor_msgs/NavSatFix`` -> perception.gps and location's WGS84 position.

    ``status.status`` -1 no fix, 0 fix (3D when altitude is known, else 2D), 1 SBAS,
    2 GBAS; Jazzy's -2 is unknown. Without a fix the coordinates are meaningless and
    are left out. NavSatFix carries no satellite count, so none is reported.
    """
    status = integer(getattr(getattr(msg, "status", None), "status", None))
    latitude = rounded(getattr(msg, "latitude", None), LATLON)
    longitude = rounded(getattr(msg, "longitude", None), LATLON)
    altitude = rounded(getattr(msg, "altitude", None), MM)
    if latitude is not None and not -90 <= latitude <= 90:
        latitude = None
    if longitude is not None and not -180 <= longitude <= 180:
        longitude = None
    fix_type = _fix_type(status, altitude)
    has_fix = fix_type not in ("no_fix", "unknown") and latitude is not None
    gps: dict[str, Any] = {"fix_type": fix_type}
    if has_fix and longitude is not None:
        gps.update(
            present(
                latitude=latitude,
                longitude=longitude,
                altitude_m=altitude,
                horizontal_accuracy_m=_horizontal_accuracy(msg),
            )
        )
    return cast(NavSatFixReading, present(**header_fields(msg), gps=gps))


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
    return snap(math.sqrt(max(east, north)), MM)


def handle_pose_stamped(msg: Any) -> GoalReading:
    """``geometry_msgs/PoseStamped`` on /goal_pose -> navigation goal."""
    head = header_fields(msg)
    pose = pose_fields(getattr(msg, "pose", None))
    return cast(GoalReading, present(**head, goal=present(frame_id=head.get("frame_id"), **pose)))


def handle_joint_state(msg: Any) -> JointStateReading:
    """``sensor_msgs/JointState`` -> actuators.joints.

    position is rad (or m for prismatic joints), velocity rad/s, effort N·m (or N).
    ROS allows the value arrays to be empty or shorter than ``name``.
    """
    names = list(sequence_items(msg, "name", MAX_JOINTS))
    columns = (
        ("position_rad", RAD, list(sequence_items(msg, "position", MAX_JOINTS))),
        ("velocity_rps", RAD_S, list(sequence_items(msg, "velocity", MAX_JOINTS))),
        ("effort", MM, list(sequence_items(msg, "effort", MAX_JOINTS))),
    )
    joints = []
    repaired = 0
    for index, name in enumerate(names):
        safe_name, name_repaired = checked_text(name)
        repaired += name_repaired
        joint: dict[str, Any] = {"name": safe_name or f"joint_{index}"}
        for key, digits, column in columns:
            value = rounded(column[index], digits) if index < len(column) else None
            if value is not None:
                joint[key] = value
        joints.append(joint)
    reading = present(**header_fields(msg), joints=joints or None)
    add_repairs(reading, repaired)
    return cast(JointStateReading, reading)
