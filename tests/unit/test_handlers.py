"""Every topic handler: known input -> known output, for rclpy, rosbags and DDS field types."""

from __future__ import annotations

import math
from typing import ClassVar

import pytest

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest import handlers as h
from phytrace_edge.ingest import robot_status
from phytrace_edge.sim.mock_ros import messages as m
from tests.flavours import as_flavour

NAN, INF = math.nan, math.inf


def header(sec: int = 1_763_000_000, nanosec: int = 500_000_000, frame: str = "odom"):
    return m.Header(stamp=m.Time(sec=sec, nanosec=nanosec), frame_id=frame)


def yaw_quaternion(deg: float):
    half = math.radians(deg) / 2
    return m.Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half))


def test_odometry_pose_twist_and_stamp(flavour: str) -> None:
    msg = m.Odometry(header=header(), child_frame_id="base_link")
    msg.pose.pose.position = m.Point(x=12.34, y=5.67, z=0.0)
    msg.pose.pose.orientation = yaw_quaternion(45.2)
    msg.twist.twist.linear = m.Vector3(x=0.85, y=0.0, z=0.0)
    msg.twist.twist.angular = m.Vector3(x=0.0, y=0.0, z=math.radians(2.1))

    reading = h.handle_odometry(as_flavour(msg, flavour))

    assert reading["stamp_ns"] == 1_763_000_000_500_000_000
    assert reading["local"]["coordinate_frame"] == "odom"
    assert reading["local"]["x_m"] == pytest.approx(12.34)
    assert reading["local"]["y_m"] == pytest.approx(5.67)
    assert reading["local"]["yaw_deg"] == pytest.approx(45.2)
    assert reading["linear_velocity"] == {"x_mps": 0.85, "y_mps": 0.0, "z_mps": 0.0}
    assert reading["angular_velocity"]["yaw_dps"] == pytest.approx(2.1)


def test_odometry_nan_position_is_left_out(flavour: str) -> None:
    msg = m.Odometry(header=header())
    msg.pose.pose.position = m.Point(x=NAN, y=1.0, z=INF)
    reading = h.handle_odometry(as_flavour(msg, flavour))
    assert "x_m" not in reading["local"] and "z_m" not in reading["local"]
    assert reading["local"]["y_m"] == 1.0


def test_battery_percentage_status_and_nan_fields(flavour: str) -> None:
    msg = m.BatteryState(
        header=header(frame="battery"),
        voltage=24.1,
        current=-2.3,
        percentage=0.825,
        temperature=28.4,
        charge=NAN,  # unmeasured by ROS convention
        capacity=NAN,
        power_supply_status=2,  # DISCHARGING
        power_supply_health=1,  # GOOD
        present=True,
        cell_voltage=[4.0, 4.1, NAN],
    )
    reading = h.handle_battery_state(as_flavour(msg, flavour))

    battery = reading["battery"]
    # float32 fields as the sensor wrote them, not 24.100000381469727
    assert battery["state_of_charge_pct"] == 82.5
    assert (battery["voltage_v"], battery["current_a"], battery["temperature_c"]) == (
        24.1,
        -2.3,
        28.4,
    )
    assert "charge_ah" not in battery and "capacity_ah" not in battery
    assert battery["health"] == "good"
    assert battery["cell_voltages_v"] == [4.0, 4.1]
    assert reading["charging"] == {"is_charging": False, "status": "discharging"}
    assert reading["power_state"] == "on_battery"


@pytest.mark.parametrize(
    ("status", "charging", "power_state"),
    [
        (1, {"is_charging": True, "status": "charging"}, "charging"),
        (3, {"is_charging": False, "status": "not_charging"}, "on_battery"),
        (4, {"is_charging": False, "status": "full"}, "full"),
        (0, None, "unknown"),
    ],
)
def test_battery_supply_status_mapping(
    flavour: str, status: int, charging: dict | None, power_state: str
) -> None:
    msg = m.BatteryState(percentage=NAN, power_supply_status=status)
    reading = h.handle_battery_state(as_flavour(msg, flavour))
    assert reading.get("charging") == charging
    assert reading["power_state"] == power_state
    assert "state_of_charge_pct" not in reading.get("battery", {})


def test_battery_percentage_outside_0_to_1_is_rejected_not_guessed() -> None:
    reading = h.handle_battery_state(m.BatteryState(percentage=82.5, voltage=24.0))
    assert "state_of_charge_pct" not in reading["battery"]
    assert reading["rejected_fields"] == ["percentage"]
    assert (
        h.handle_battery_state(m.BatteryState(percentage=1.0))["battery"]["state_of_charge_pct"]
        == 100.0
    )


def test_laser_scan_valid_returns_rule(flavour: str) -> None:
    # beams: 0.05 below range_min, NaN, inf, 15 above range_max, then 3 valid returns
    ranges = [0.05, NAN, INF, 15.0, 2.0, 0.5, 11.9]
    msg = m.LaserScan(
        header=header(frame="front_lidar"),
        angle_min=-math.pi / 2,
        angle_max=math.pi / 2,
        angle_increment=math.pi / 6,
        range_min=0.12,
        range_max=12.0,
        ranges=ranges,
    )
    lidar = h.handle_laser_scan(as_flavour(msg, flavour))["lidar"]

    assert lidar["sensor_id"] == "front_lidar"
    assert lidar["min_range_m"] == 0.12  # 0.12f arrives as 0.11999999731779099
    assert lidar["max_range_m"] == 12.0
    assert lidar["num_points"] == 7
    assert lidar["valid_points"] == 3
    assert lidar["closest_range_m"] == pytest.approx(0.5)
    # beam 5 at -90 + 5 * 30 degrees
    assert lidar["closest_bearing_deg"] == pytest.approx(60.0, abs=1e-4)


def test_laser_scan_with_no_valid_return_has_no_closest(flavour: str) -> None:
    msg = m.LaserScan(range_min=0.1, range_max=10.0, ranges=[INF, NAN, 0.01])
    lidar = h.handle_laser_scan(as_flavour(msg, flavour))["lidar"]
    assert lidar["valid_points"] == 0
    assert "closest_range_m" not in lidar
    assert lidar["num_points"] == 3


def test_laser_scan_with_broken_bounds_counts_positive_finite_returns() -> None:
    msg = m.LaserScan(range_min=NAN, range_max=INF, ranges=[1.0, -1.0, 0.0, INF])
    lidar = h.handle_laser_scan(msg)["lidar"]
    assert "min_range_m" not in lidar and "max_range_m" not in lidar
    assert lidar["valid_points"] == 1


def test_laser_scan_ranges_of_text_is_malformed() -> None:
    class Scan:
        ranges: ClassVar[list[str]] = ["far", "near"]

    with pytest.raises(MalformedMessage) as info:
        h.handle_laser_scan(Scan())
    assert info.value.reason == "bad_ranges"


def test_imu_orientation_rates_and_acceleration(flavour: str) -> None:
    # roll 10, pitch -20, yaw 30 degrees (intrinsic z-y-x)
    r, p, y = (math.radians(a) / 2 for a in (10.0, -20.0, 30.0))
    q = m.Quaternion(
        x=math.sin(r) * math.cos(p) * math.cos(y) - math.cos(r) * math.sin(p) * math.sin(y),
        y=math.cos(r) * math.sin(p) * math.cos(y) + math.sin(r) * math.cos(p) * math.sin(y),
        z=math.cos(r) * math.cos(p) * math.sin(y) - math.sin(r) * math.sin(p) * math.cos(y),
        w=math.cos(r) * math.cos(p) * math.cos(y) + math.sin(r) * math.sin(p) * math.sin(y),
    )
    msg = m.Imu(
        header=header(frame="imu_link"),
        orientation=q,
        angular_velocity=m.Vector3(x=0.0, y=0.0, z=math.radians(2.1)),
        linear_acceleration=m.Vector3(x=0.05, y=0.01, z=9.81),
    )
    imu = h.handle_imu(as_flavour(msg, flavour))["imu"]
    assert imu["orientation_deg"]["roll"] == pytest.approx(10.0)
    assert imu["orientation_deg"]["pitch"] == pytest.approx(-20.0)
    assert imu["orientation_deg"]["yaw"] == pytest.approx(30.0)
    assert imu["angular_velocity_dps"] == pytest.approx({"x": 0.0, "y": 0.0, "z": 2.1})
    assert imu["linear_acceleration_mps2"] == {"x": 0.05, "y": 0.01, "z": 9.81}


def test_imu_without_orientation_per_rep145(flavour: str) -> None:
    msg = m.Imu(orientation_covariance=[-1.0] + [0.0] * 8)
    imu = h.handle_imu(as_flavour(msg, flavour))["imu"]
    assert "orientation_deg" not in imu


def test_twist_and_twist_stamped(flavour: str) -> None:
    twist = m.Twist(linear=m.Vector3(x=1.0, y=0.2, z=0.0), angular=m.Vector3(z=-0.5))
    reading = h.handle_twist(as_flavour(twist, flavour))
    assert reading["commanded_velocity"] == {
        "linear_x_mps": 1.0,
        "linear_y_mps": 0.2,
        "angular_z_rps": -0.5,
    }
    assert "stamp_ns" not in reading
    stamped = h.handle_twist(m.TwistStamped(header=header(), twist=twist))
    assert stamped["commanded_velocity"]["angular_z_rps"] == -0.5
    assert stamped["stamp_ns"] == 1_763_000_000_500_000_000


@pytest.mark.parametrize(
    ("status", "altitude", "fix_type"),
    [
        (-1, 182.5, "no_fix"),
        (0, 182.5, "3d_fix"),
        (0, NAN, "2d_fix"),
        (1, 1.0, "sbas_fix"),
        (2, 1.0, "gbas_fix"),
        (-2, 1.0, "unknown"),
    ],
)
def test_nav_sat_fix_status_mapping(
    flavour: str, status: int, altitude: float, fix_type: str
) -> None:
    msg = m.NavSatFix(
        header=header(frame="gps"),
        status=m.NavSatStatus(status=status, service=1),
        latitude=41.8781,
        longitude=-87.6298,
        altitude=altitude,
        position_covariance=[4.0, 0, 0, 0, 9.0, 0, 0, 0, 16.0],
        position_covariance_type=2,
    )
    gps = h.handle_nav_sat_fix(as_flavour(msg, flavour))["gps"]
    assert gps["fix_type"] == fix_type
    if fix_type in ("no_fix", "unknown"):
        assert "latitude" not in gps and "longitude" not in gps
    else:
        assert (gps["latitude"], gps["longitude"]) == (41.8781, -87.6298)
        assert gps["horizontal_accuracy_m"] == pytest.approx(3.0)
        assert ("altitude_m" in gps) == (fix_type != "2d_fix")


def test_nav_sat_fix_out_of_range_coordinates_are_dropped() -> None:
    msg = m.NavSatFix(status=m.NavSatStatus(status=0), latitude=91.0, longitude=10.0)
    gps = h.handle_nav_sat_fix(msg)["gps"]
    assert "latitude" not in gps


def test_diagnostics_levels_from_bytes_and_ints(flavour: str) -> None:
    statuses = [
        m.DiagnosticStatus(level=level, name=f"n{i}", message=f"msg{i}", hardware_id="hw")
        for i, level in enumerate((b"\x00", b"\x01", b"\x02", b"\x03", b"\x07"))
    ]
    msg = m.DiagnosticArray(header=header(frame=""), status=statuses)
    reading = robot_status.handle_diagnostic_array(as_flavour(msg, flavour))
    assert [s["level"] for s in reading["statuses"]] == ["ok", "warn", "error", "stale", "unknown"]
    assert reading["statuses"][2] == {
        "name": "n2",
        "level": "error",
        "message": "msg2",
        "hardware_id": "hw",
    }


def test_goal_pose(flavour: str) -> None:
    msg = m.PoseStamped(header=header(frame="map"))
    msg.pose.position = m.Point(x=45.0, y=22.0, z=0.0)
    msg.pose.orientation = yaw_quaternion(90.0)
    goal = h.handle_pose_stamped(as_flavour(msg, flavour))["goal"]
    assert goal == pytest.approx(
        {"frame_id": "map", "x_m": 45.0, "y_m": 22.0, "z_m": 0.0, "yaw_deg": 90.0}
    )


def test_joint_states_with_short_arrays(flavour: str) -> None:
    msg = m.JointState(
        header=header(frame="base"),
        name=["left_wheel", "right_wheel", "lift"],
        position=[3.14, 3.15, 0.2],
        velocity=[2.5, NAN],
        effort=[],
    )
    joints = h.handle_joint_state(as_flavour(msg, flavour))["joints"]
    assert joints == [
        {"name": "left_wheel", "position_rad": 3.14, "velocity_rps": 2.5},
        {"name": "right_wheel", "position_rad": 3.15},
        {"name": "lift", "position_rad": 0.2},
    ]


def test_delivery_status_json(flavour: str) -> None:
    data = (
        '{"order_id": "order-8821", "package_id": "pkg-5501", "state": "in_transit",'
        ' "destination": "dock-B3", "task_type": "delivery", "task_status": "in_progress",'
        ' "robot_state": "autonomous"}'
    )
    reading = robot_status.handle_delivery_status(as_flavour(m.String(data=data), flavour))
    assert reading["payload"] == {
        "order_id": "order-8821",
        "package_id": "pkg-5501",
        "delivery_state": "in_transit",
        "destination": "dock-B3",
    }
    assert reading["task"] == {
        "task_id": "order-8821",
        "task_type": "delivery",
        "status": "in_progress",
        "payload_id": "pkg-5501",
    }
    assert reading["state"] == "autonomous"
    assert "rejected_fields" not in reading


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        ("{not json", "bad_json"),
        ("[1, 2]", "not_object"),
        ('"text"', "not_object"),
        ("x" * (robot_status.DELIVERY_STATUS_MAX_BYTES + 1), "too_large"),
    ],
)
def test_delivery_status_malformed(data: str, reason: str) -> None:
    with pytest.raises(MalformedMessage) as info:
        robot_status.handle_delivery_status(m.String(data=data))
    assert info.value.reason == reason


def test_delivery_status_wrong_field_types_keep_the_rest() -> None:
    data = (
        '{"order_id": 8821, "state": ["x"], "destination": "' + "d" * 300 + '", "task_type": 1.5}'
    )
    reading = robot_status.handle_delivery_status(m.String(data=data))
    assert reading["payload"] == {"order_id": "8821"}
    assert sorted(reading["rejected_fields"]) == ["destination", "state", "task_type"]
