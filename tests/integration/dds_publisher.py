"""A plain Cyclone DDS robot for the DDS source's test (run as a script): publishes the
ten topics with known values, ROS 2 wire names and types, until stdin closes; and, for
TOPICS_EXTRA, the known messages of the generic conversion's test (``EXTRA``) and a
log record on /rosout.

    dds_publisher.py     (ROS_DOMAIN_ID and ROS_LOCALHOST_ONLY come from the environment)
"""

from __future__ import annotations

import math
import os
import sys
import threading

import orjson
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from phytrace_edge.ingest.sources import dds_types as t
from phytrace_edge.ingest.sources.dds import LOCALHOST_CONFIG, dds_topic_name, domain_settings

BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
RELIABLE = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)), Policy.History.KeepLast(10)
)


def header(frame: str) -> t.Header_:
    return t.Header_(stamp=t.Time_(sec=1_763_000_000, nanosec=500_000_000), frame_id=frame)


def yaw(deg: float) -> t.Quaternion_:
    half = math.radians(deg) / 2
    return t.Quaternion_(z=math.sin(half), w=math.cos(half))


def samples() -> dict[str, tuple[object, Qos]]:
    odom = t.Odometry_(header=header("odom"), child_frame_id="base_link")
    odom.pose.pose = t.Pose_(position=t.Point_(x=12.34, y=5.67), orientation=yaw(45.2))
    odom.twist.twist = t.Twist_(linear=t.Vector3_(x=0.85), angular=t.Vector3_(z=math.radians(2.1)))
    delivery = {
        "order_id": "order-8821",
        "package_id": "pkg-5501",
        "state": "in_transit",
        "destination": "dock-B3",
        "robot_state": "autonomous",
    }
    return {
        "/odom": (odom, BEST_EFFORT),
        "/battery_state": (
            t.BatteryState_(
                header=header("battery"),
                voltage=24.1,
                current=-2.3,
                percentage=0.825,
                temperature=28.4,
                charge=math.nan,
                power_supply_status=2,
                present=True,
                cell_voltage=[4.0, 4.1],
            ),
            RELIABLE,
        ),
        "/scan": (
            t.LaserScan_(
                header=header("front_lidar"),
                angle_min=-math.pi / 2,
                angle_max=math.pi / 2,
                angle_increment=math.pi / 4,
                range_min=0.12,
                range_max=12.0,
                ranges=[0.05, math.nan, math.inf, 2.0, 0.5],
            ),
            BEST_EFFORT,
        ),
        "/imu/data": (
            t.Imu_(
                header=header("imu"),
                orientation=yaw(30.0),
                angular_velocity=t.Vector3_(z=math.radians(2.1)),
                linear_acceleration=t.Vector3_(z=9.81),
            ),
            BEST_EFFORT,
        ),
        "/cmd_vel": (t.Twist_(linear=t.Vector3_(x=1.0), angular=t.Vector3_(z=-0.5)), RELIABLE),
        "/gps/fix": (
            t.NavSatFix_(
                header=header("gps"),
                status=t.NavSatStatus_(status=0),
                latitude=41.8781,
                longitude=-87.6298,
                altitude=182.5,
            ),
            BEST_EFFORT,
        ),
        "/diagnostics": (
            t.DiagnosticArray_(
                header=header(""),
                status=[
                    t.DiagnosticStatus_(
                        level=2, name="motor", message="overcurrent", hardware_id="mc"
                    ),
                    t.DiagnosticStatus_(level=0, name="lidar", message="ok", hardware_id="l1"),
                ],
            ),
            RELIABLE,
        ),
        "/goal_pose": (
            t.PoseStamped_(
                header=header("map"),
                pose=t.Pose_(position=t.Point_(x=45.0, y=22.0), orientation=yaw(90.0)),
            ),
            RELIABLE,
        ),
        "/joint_states": (
            t.JointState_(
                header=header("base"),
                name=["left_wheel", "right_wheel"],
                position=[3.14, 3.15],
                velocity=[2.5, 2.5],
            ),
            BEST_EFFORT,
        ),
        "/delivery/status": (t.String_(data=orjson.dumps(delivery).decode()), RELIABLE),
    }


def extra_samples() -> dict[str, tuple[object, Qos]]:
    """Messages of types outside the table, in the types the dds input makes itself."""
    from tests.unit.test_generic import (
        compressed_image,
        float32_array,
        temperature,
        tf_message,
        to_idl,
    )

    log = t.Log_(
        stamp=t.Time_(sec=1_763_000_000), level=40, name="acme.drive", msg="overcurrent", line=7
    )
    return {
        EXTRA["/motor/temperature"]: (to_idl(temperature()), RELIABLE),
        EXTRA["/tf"]: (to_idl(tf_message()), BEST_EFFORT),
        EXTRA["/cells"]: (to_idl(float32_array()), BEST_EFFORT),
        EXTRA["/camera"]: (to_idl(compressed_image()), BEST_EFFORT),
        "/rosout": (log, RELIABLE),
    }


# extra topic -> its name on the wire (here, the same)
EXTRA = {t: t for t in ("/motor/temperature", "/tf", "/cells", "/camera")}


def main() -> None:
    domain_id, localhost = domain_settings(os.environ)
    domain = Domain(domain_id, LOCALHOST_CONFIG) if localhost else None
    participant = DomainParticipant(domain_id)
    writers = []
    for topic_name, (sample, qos) in (samples() | extra_samples()).items():
        topic = Topic(participant, dds_topic_name(topic_name), type(sample))
        writers.append((DataWriter(participant, topic, qos=qos), sample))
    print("ready", flush=True)
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    while not done.wait(0.05):  # 20 Hz, as a robot would
        for writer, sample in writers:
            writer.write(sample)
    del domain


if __name__ == "__main__":
    main()
