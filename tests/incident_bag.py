"""A rosbag2 of a robot that hits something: /odom at 50 Hz and /imu/data at 100 Hz for
``seconds``, /diagnostics once a second, OK until ``error_at_s`` and ERROR from then
on, written with rosbags as ``ros2 bag record`` would. Each /odom message's forward
speed says which message it is (``speed_of(n)``), so a test can check that every
sample of an incident is exactly the message published."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

BAG_START_S = 1_790_000_000  # 2026-09-21, the bag's first moment (bag time)
ODOM_HZ, IMU_HZ = 50, 100


def speed_of(n: int) -> float:
    """The forward speed of the n-th /odom message: exact at the handler's mm/s."""
    return round((n % 2000) / 1000, 3)


def yaw_rate_of(n: int) -> float:
    """The IMU's z rate of the n-th /imu/data message, in rad/s (degrees: an integer)."""
    return float(np.radians(n % 90))


def write_incident_bag(
    path: Path,
    seconds: int = 120,
    error_at_s: int = 60,
    odom_hz: int = ODOM_HZ,
    imu_hz: int = IMU_HZ,
    diagnostics_every_s: int = 1,
) -> dict[str, int]:
    """Write the bag at ``path`` (a directory); messages per topic. Slower rates make a
    bag of hours small (the long outage's)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    t = store.types

    def header(ns: int, frame: str) -> Any:
        stamp = t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def vector(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
        return t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def odometry(n: int, ns: int) -> Any:
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=n / 100, y=0.0, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        twist = t["geometry_msgs/msg/Twist"](linear=vector(speed_of(n)), angular=vector())
        return t["nav_msgs/msg/Odometry"](
            header=header(ns, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )

    def imu(n: int, ns: int) -> Any:
        return t["sensor_msgs/msg/Imu"](
            header=header(ns, "imu_link"),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9),
            angular_velocity=vector(z=yaw_rate_of(n)),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vector(z=9.81),
            linear_acceleration_covariance=np.zeros(9),
        )

    def diagnostics(second: int, ns: int) -> Any:
        error = second >= error_at_s
        status = t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=b"\x02"[0] if error else 0,
            name="bumper",
            message="contact: hit an obstacle" if error else "clear",
            hardware_id="bumper-front",
            values=[],
        )
        return t["diagnostic_msgs/msg/DiagnosticArray"](header=header(ns, ""), status=[status])

    records: list[tuple[int, str, Any]] = []
    start_ns = BAG_START_S * 10**9
    records += [(start_ns + n * 10**9 // odom_hz, "/odom", n) for n in range(seconds * odom_hz)]
    records += [(start_ns + n * 10**9 // imu_hz, "/imu/data", n) for n in range(seconds * imu_hz)]
    records += [
        (start_ns + s * 10**9, "/diagnostics", s) for s in range(0, seconds, diagnostics_every_s)
    ]
    records.sort(key=lambda record: (record[0], record[1]))
    build = {"/odom": odometry, "/imu/data": imu, "/diagnostics": diagnostics}
    types = {
        "/odom": "nav_msgs/msg/Odometry",
        "/imu/data": "sensor_msgs/msg/Imu",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    }
    counts: dict[str, int] = {}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            topic: writer.add_connection(topic, msgtype, typestore=store)
            for topic, msgtype in types.items()
        }
        for ns, topic, n in records:
            data = store.serialize_cdr(build[topic](n, ns), types[topic])
            writer.write(connections[topic], ns, data)
            counts[topic] = counts.get(topic, 0) + 1
    return counts
