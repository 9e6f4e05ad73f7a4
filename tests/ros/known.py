"""The ten topics with known values, as plain data, and what the bridge must make of them.

Every robot of the tests publishes these: the Cyclone DDS publisher
(``tests/integration/dds_publisher.py``), the rclpy robot (``tests/ros/robot.py`` on
real rclpy or on the mock). ``check_known_event`` compares the event built from them
field by field.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from phytrace_edge.builder.assemble import DOMAINS

STAMP = {"sec": 1_763_000_000, "nanosec": 500_000_000}
STAMP_TEXT = "2025-11-13T02:13:20.500Z"


def header(frame: str) -> dict[str, Any]:
    return {"stamp": STAMP, "frame_id": frame}


def yaw(deg: float) -> dict[str, float]:
    half = math.radians(deg) / 2
    return {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}


DELIVERY = {
    "order_id": "order-8821",
    "package_id": "pkg-5501",
    "state": "in_transit",
    "destination": "dock-B3",
    "robot_state": "autonomous",
}

# topic -> (type, QoS offered: "best_effort", "reliable" or "latched", fields)
KNOWN: dict[str, tuple[str, str, dict[str, Any]]] = {
    "/odom": (
        "nav_msgs/msg/Odometry",
        "best_effort",
        {
            "header": header("odom"),
            "child_frame_id": "base_link",
            "pose": {"pose": {"position": {"x": 12.34, "y": 5.67}, "orientation": yaw(45.2)}},
            "twist": {"twist": {"linear": {"x": 0.85}, "angular": {"z": math.radians(2.1)}}},
        },
    ),
    "/battery_state": (
        "sensor_msgs/msg/BatteryState",
        "reliable",
        {
            "header": header("battery"),
            "voltage": 24.1,
            "current": -2.3,
            "percentage": 0.825,
            "temperature": 28.4,
            "charge": math.nan,
            "power_supply_status": 2,
            "present": True,
            "cell_voltage": [4.0, 4.1],
        },
    ),
    "/scan": (
        "sensor_msgs/msg/LaserScan",
        "best_effort",
        {
            "header": header("front_lidar"),
            "angle_min": -math.pi / 2,
            "angle_max": math.pi / 2,
            "angle_increment": math.pi / 4,
            "range_min": 0.12,
            "range_max": 12.0,
            "ranges": [0.05, math.nan, math.inf, 2.0, 0.5],
        },
    ),
    "/imu/data": (
        "sensor_msgs/msg/Imu",
        "best_effort",
        {
            "header": header("imu"),
            "orientation": yaw(30.0),
            "angular_velocity": {"z": math.radians(2.1)},
            "linear_acceleration": {"z": 9.81},
        },
    ),
    "/cmd_vel": (
        "geometry_msgs/msg/Twist",
        "reliable",
        {"linear": {"x": 1.0}, "angular": {"z": -0.5}},
    ),
    "/gps/fix": (
        "sensor_msgs/msg/NavSatFix",
        "best_effort",
        {
            "header": header("gps"),
            "status": {"status": 0},
            "latitude": 41.8781,
            "longitude": -87.6298,
            "altitude": 182.5,
        },
    ),
    "/diagnostics": (
        "diagnostic_msgs/msg/DiagnosticArray",
        "reliable",
        {
            "header": header(""),
            "status": [
                {"level": 2, "name": "motor", "message": "overcurrent", "hardware_id": "mc"},
                {"level": 0, "name": "lidar", "message": "ok", "hardware_id": "l1"},
            ],
        },
    ),
    "/goal_pose": (
        "geometry_msgs/msg/PoseStamped",
        "latched",
        {
            "header": header("map"),
            "pose": {"position": {"x": 45.0, "y": 22.0}, "orientation": yaw(90.0)},
        },
    ),
    "/joint_states": (
        "sensor_msgs/msg/JointState",
        "best_effort",
        {
            "header": header("base"),
            "name": ["left_wheel", "right_wheel"],
            "position": [3.14, 3.15],
            "velocity": [2.5, 2.5],
        },
    ),
    "/delivery/status": (
        "std_msgs/msg/String",
        "reliable",
        {"data": json.dumps(DELIVERY)},
    ),
}  # fmt: skip


def carries_every_known_value(event: dict[str, Any]) -> bool:
    """Whether ``check_known_event`` can be asked of ``event``: every domain, and the
    diagnostics ERROR. An event can have every domain before the first diagnostics
    message arrived (``operational`` from /delivery/status alone), so a domain count
    is not enough to wait on."""
    return set(DOMAINS) <= set(event) and bool(event["operational"].get("errors"))


def check_known_event(event: dict[str, Any]) -> None:
    """The event built from ``KNOWN``, field by field."""
    assert event["location"]["local"] == pytest.approx(
        {"coordinate_frame": "odom", "x_m": 12.34, "y_m": 5.67, "z_m": 0.0, "yaw_deg": 45.2}
    )
    assert event["location"]["latitude"] == 41.8781
    assert event["location"]["longitude"] == -87.6298
    assert event["motion"]["linear_velocity"]["x_mps"] == 0.85
    assert event["motion"]["commanded_velocity"] == {
        "linear_x_mps": 1.0,
        "linear_y_mps": 0.0,
        "angular_z_rps": -0.5,
    }
    battery = event["power"]["battery"]
    assert battery["state_of_charge_pct"] == pytest.approx(82.5)
    assert battery["voltage_v"] == pytest.approx(24.1, rel=1e-6)
    assert event["power"]["charging"]["is_charging"] is False  # status 2: discharging
    assert "charge_ah" not in battery  # NaN on the wire
    lidar = event["perception"]["lidar"][0]
    assert (lidar["num_points"], lidar["valid_points"]) == (5, 2)
    assert lidar["closest_range_m"] == pytest.approx(0.5)
    assert (lidar["min_range_m"], lidar["max_range_m"]) == pytest.approx((0.12, 12.0))
    assert event["perception"]["imu"]["orientation_deg"]["yaw"] == pytest.approx(30.0)
    errors = event["operational"]["errors"]
    assert [(e["name"], e["level"]) for e in errors] == [("motor", "error")]
    assert event["navigation"]["goal"]["x_m"] == 45.0
    assert event["navigation"]["goal"]["y_m"] == 22.0
    joints = event["actuators"]["joints"]
    assert [(j["name"], j["position_rad"], j["velocity_rps"]) for j in joints] == [
        ("left_wheel", 3.14, 2.5),
        ("right_wheel", 3.15, 2.5),
    ]
    assert event["payload"]["delivery_state"] == "in_transit"
    assert event["location"]["sources"][0]["stamp"] == STAMP_TEXT
