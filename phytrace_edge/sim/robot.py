"""The simulated delivery robot as a ROS 2 node: publishes the ten topics from ``World``.

Rates follow a typical delivery base: odometry, IMU, command velocity, scan and joint
states at ``tick_hz`` (10 Hz), GPS at 5 Hz, battery and diagnostics at 1 Hz, the
delivery status at 1 Hz and on every state change, and a goal whenever one is set.
Sensors publish best effort (as real drivers do); status topics are reliable.
"""

from __future__ import annotations

import math
from typing import Any

import orjson

from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.sim.mock_ros.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from phytrace_edge.sim.mock_ros.runtime import Node
from phytrace_edge.sim.world import ORIGIN_ALT, World

SCAN_BEAMS = 360
SCAN_RANGE_MIN_M = 0.12
SCAN_RANGE_MAX_M = 12.0
LOG_INFO, LOG_WARN, LOG_ERROR = 20, 30, 40  # rcl_interfaces/msg/Log's levels
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


def _quaternion_from_yaw(yaw: float) -> Any:
    return m.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


class DeliveryRobot:
    """Publishes the robot's topics on ``node``; call ``tick()`` at ``tick_hz``."""

    def __init__(self, node: Node, world: World, tick_hz: float = 10.0) -> None:
        self.node, self.world, self.tick_hz = node, world, tick_hz
        self.ticks = 0
        self._last_goal_serial = 0
        self._last_state = ""
        sensor = qos_profile_sensor_data
        self.pub = {
            "/odom": node.create_publisher(m.Odometry, "/odom", sensor),
            "/imu/data": node.create_publisher(m.Imu, "/imu/data", sensor),
            "/scan": node.create_publisher(m.LaserScan, "/scan", sensor),
            "/cmd_vel": node.create_publisher(m.Twist, "/cmd_vel", RELIABLE),
            "/joint_states": node.create_publisher(m.JointState, "/joint_states", RELIABLE),
            "/gps/fix": node.create_publisher(m.NavSatFix, "/gps/fix", sensor),
            "/battery_state": node.create_publisher(m.BatteryState, "/battery_state", RELIABLE),
            "/diagnostics": node.create_publisher(m.DiagnosticArray, "/diagnostics", RELIABLE),
            "/goal_pose": node.create_publisher(m.PoseStamped, "/goal_pose", LATCHED),
            "/delivery/status": node.create_publisher(m.String, "/delivery/status", LATCHED),
            # beyond the table: the robot's log, and a topic for TOPICS_EXTRA
            "/rosout": node.create_publisher(m.Log, "/rosout", LATCHED),
            "/motor/temperature": node.create_publisher(
                m.Temperature, "/motor/temperature", RELIABLE
            ),
        }
        self._logged_faults: set[str] = set()
        self._battery_warned = False

    def tick(self) -> None:
        """Advance the world one step and publish what is due."""
        self.world.step(1.0 / self.tick_hz)
        self.ticks += 1
        per_second = self.ticks % round(self.tick_hz) == 0
        self.publish_motion()
        if self.ticks % max(1, round(self.tick_hz / 5)) == 0:
            self.pub["/gps/fix"].publish(self.nav_sat_fix())
        if per_second:
            self.pub["/battery_state"].publish(self.battery_state())
            self.pub["/diagnostics"].publish(self.diagnostics())
            self.pub["/motor/temperature"].publish(self.motor_temperature())
        self.publish_logs()
        if self.world.goal is not None and self.world.goal_serial != self._last_goal_serial:
            self._last_goal_serial = self.world.goal_serial
            self.pub["/goal_pose"].publish(self.goal_pose())
        if per_second or self.world.state != self._last_state:
            self._last_state = self.world.state
            self.pub["/delivery/status"].publish(self.delivery_status())

    def _header(self, frame_id: str) -> Any:
        return m.Header(stamp=self.node.get_clock().now().to_msg(), frame_id=frame_id)

    def publish_motion(self) -> None:
        self.pub["/odom"].publish(self.odometry())
        self.pub["/imu/data"].publish(self.imu())
        self.pub["/cmd_vel"].publish(self.cmd_vel())
        self.pub["/scan"].publish(self.laser_scan())
        self.pub["/joint_states"].publish(self.joint_state())

    def odometry(self) -> Any:
        w = self.world
        msg = m.Odometry(header=self._header("odom"), child_frame_id="base_link")
        msg.pose.pose.position = m.Point(x=w.x, y=w.y, z=0.0)
        msg.pose.pose.orientation = _quaternion_from_yaw(w.yaw)
        msg.twist.twist.linear = m.Vector3(x=w.v, y=0.0, z=0.0)
        msg.twist.twist.angular = m.Vector3(x=0.0, y=0.0, z=w.yaw_rate)
        msg.pose.covariance = [0.01 if i % 7 == 0 else 0.0 for i in range(36)]
        return msg

    def imu(self) -> Any:
        w = self.world
        return m.Imu(
            header=self._header("imu_link"),
            orientation=_quaternion_from_yaw(w.yaw),
            orientation_covariance=[0.001, 0, 0, 0, 0.001, 0, 0, 0, 0.002],
            angular_velocity=m.Vector3(x=0.0, y=0.0, z=w.yaw_rate),
            linear_acceleration=m.Vector3(x=w.accel, y=w.v * w.yaw_rate, z=9.81),
        )

    def cmd_vel(self) -> Any:
        w = self.world
        return m.Twist(
            linear=m.Vector3(x=w.cmd_v, y=0.0, z=0.0),
            angular=m.Vector3(x=0.0, y=0.0, z=w.cmd_yaw_rate),
        )

    def laser_scan(self) -> Any:
        return m.LaserScan(
            header=self._header("front_lidar"),
            angle_min=-math.pi,
            angle_max=math.pi - 2 * math.pi / SCAN_BEAMS,
            angle_increment=2 * math.pi / SCAN_BEAMS,
            scan_time=0.1,
            range_min=SCAN_RANGE_MIN_M,
            range_max=SCAN_RANGE_MAX_M,
            ranges=self.world.scan_ranges(SCAN_BEAMS, SCAN_RANGE_MIN_M, SCAN_RANGE_MAX_M),
        )

    def joint_state(self) -> Any:
        w = self.world
        left, right = w.wheel_rates()
        return m.JointState(
            header=self._header("base_link"),
            name=["left_wheel", "right_wheel"],
            position=[w.wheel_left_rad, w.wheel_right_rad],
            velocity=[left, right],
            effort=[],
        )

    def nav_sat_fix(self) -> Any:
        w = self.world
        lat, lon = w.lat_lon()
        no_fix = w.gps_lost_s > 0
        return m.NavSatFix(
            header=self._header("gps_link"),
            status=m.NavSatStatus(status=-1 if no_fix else 0, service=1),
            latitude=math.nan if no_fix else lat,
            longitude=math.nan if no_fix else lon,
            altitude=math.nan if no_fix else ORIGIN_ALT,
            position_covariance=[2.25, 0, 0, 0, 2.25, 0, 0, 0, 9.0],
            position_covariance_type=2,
        )

    def battery_state(self) -> Any:
        w = self.world
        return m.BatteryState(
            header=self._header("battery"),
            voltage=w.voltage_v(),
            current=w.current_a(),
            temperature=28.0 + 2.0 * abs(w.v) + w.rng.gauss(0, 0.1),
            charge=math.nan,  # unmeasured, as ROS specifies
            capacity=math.nan,
            design_capacity=40.0,
            percentage=w.soc_pct / 100.0,
            power_supply_status=1 if w.charging else 2,
            power_supply_health=1,
            power_supply_technology=2,
            present=True,
            cell_voltage=[w.voltage_v() / 6] * 6,
        )

    def diagnostics(self) -> Any:
        w = self.world
        statuses = [
            m.DiagnosticStatus(
                level=b"\x01" if w.soc_pct < 20 else b"\x00",
                name="battery",
                message="low charge" if w.soc_pct < 20 else "ok",
                hardware_id="bms",
            )
        ]
        faulted = {fault.name for fault in w.faults}
        for fault in w.faults:
            statuses.append(
                m.DiagnosticStatus(
                    level=bytes([fault.level]),
                    name=fault.name,
                    message=fault.message,
                    hardware_id=fault.hardware_id,
                )
            )
        for name, hardware_id in (("motor_controller", "mc-left"), ("wifi", "wlan0")):
            if name not in faulted:
                statuses.append(
                    m.DiagnosticStatus(
                        level=b"\x00", name=name, message="ok", hardware_id=hardware_id
                    )
                )
        return m.DiagnosticArray(header=self._header(""), status=statuses)

    def motor_temperature(self) -> Any:
        """The left drive motor warms with speed."""
        celsius = round(35.0 + 12.0 * abs(self.world.v), 1)
        return m.Temperature(header=self._header("left_motor"), temperature=celsius, variance=0.25)

    def publish_logs(self) -> None:
        """What the robot's nodes log: an ERROR or WARN when a fault appears, a WARN
        when the battery runs low, an INFO at each task state change."""
        w = self.world
        for fault in w.faults:
            if fault.name not in self._logged_faults:
                level = LOG_ERROR if fault.level >= 2 else LOG_WARN
                self._log(
                    level, f"delivery_robot.{fault.name}", f"{fault.hardware_id}: {fault.message}"
                )
        self._logged_faults = {fault.name for fault in w.faults}
        if w.soc_pct < 20 and not self._battery_warned:
            self._log(
                LOG_WARN,
                "delivery_robot.battery",
                f"battery low ({w.soc_pct:.0f} %), docking after this task",
            )
        self._battery_warned = w.soc_pct < 20
        if w.state != self._last_state:
            self._log(
                LOG_INFO,
                "delivery_robot.mission",
                f"task state {self._last_state or 'start'} -> {w.state}",
            )

    def _log(self, level: int, logger: str, text: str) -> None:
        self.pub["/rosout"].publish(
            m.Log(
                stamp=self.node.get_clock().now().to_msg(),
                level=level,
                name=logger,
                msg=text,
                file="robot.py",
                function="publish_logs",
                line=1,
            )
        )

    def goal_pose(self) -> Any:
        _, x, y = self.world.goal  # type: ignore[misc]
        heading = math.atan2(y - self.world.y, x - self.world.x)
        msg = m.PoseStamped(header=self._header("map"))
        msg.pose.position = m.Point(x=x, y=y, z=0.0)
        msg.pose.orientation = _quaternion_from_yaw(heading)
        return msg

    def delivery_status(self) -> Any:
        w = self.world
        document = {
            "order_id": w.order_id,
            "package_id": w.package_id,
            "state": w.state,
            "destination": w.destination,
            "task_type": "delivery",
            "task_status": w.task_status,
            "robot_state": w.robot_state,
        }
        return m.String(data=orjson.dumps(document).decode())
