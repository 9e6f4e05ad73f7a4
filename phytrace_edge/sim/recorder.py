"""Record the simulated robot into a rosbag2 (``phytrace-edge sim --record PATH``): a
real bag to try replay with, and the fixtures of the replay tests.

Messages are converted from the mock's rclpy types to the rosbags Jazzy types and
serialised to CDR, so the bag is what ``ros2 bag record`` would have written.
"""

from __future__ import annotations

import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from phytrace_edge.sim.mock_ros import (
    Clock,
    ClockType,
    Context,
    SingleThreadedExecutor,
    create_node,
    init,
    qos,
    shutdown,
)
from phytrace_edge.sim.mock_ros.messages import Message
from phytrace_edge.sim.robot import DeliveryRobot
from phytrace_edge.sim.world import World

# A message type no table and no type store knows: replay must skip it with a count.
CUSTOM_TYPE = "acme_msgs/msg/Widget"
CUSTOM_DEFINITION = "string name\nfloat64 level\n"
CUSTOM_TOPIC = "/acme/widget"


def to_rosbags(msg: Message, typestore: Any) -> Any:
    """A mock (rclpy-typed) message as the rosbags type store's message."""
    cls = typestore.types[msg._type]
    return cls(
        **{
            name: _rosbags_value(getattr(msg, name), typestore)
            for name in msg._fields_and_field_types
        }
    )


def _rosbags_value(value: Any, typestore: Any) -> Any:
    if isinstance(value, Message):
        return to_rosbags(value, typestore)
    if isinstance(value, bytes):
        return value[0]
    if isinstance(value, array.array):
        return np.array(value, dtype=np.dtype(value.typecode))  # 'f' float32, 'B' uint8, ...
    if isinstance(value, list):
        return [_rosbags_value(item, typestore) for item in value]
    return value


def simulate(seconds: float, seed: int = 0) -> list[tuple[str, int, Message]]:
    """Run the simulated robot for ``seconds`` of virtual time; every message it
    published as a subscriber received it: (topic, wall-clock ns, message)."""
    records: list[tuple[str, int, Message]] = []
    # a recording, not a test of discovery: the recorder's side matches with the robot's
    context = Context(virtual_time=True, subscription_side_lag_s=0.0)
    init(context=context)
    try:
        robot_node = create_node("delivery_robot", context=context)
        robot = DeliveryRobot(robot_node, World.create(seed))
        steady = Clock(clock_type=ClockType.STEADY_TIME, source=context.time_source)
        robot_node.create_timer(1.0 / robot.tick_hz, robot.tick, clock=steady)
        recorder = create_node("recorder", context=context)
        system = Clock(clock_type=ClockType.SYSTEM_TIME, source=context.time_source)

        def keep(topic: str) -> Callable[[Message], None]:
            return lambda msg: records.append((topic, system.now().nanoseconds, msg))

        for topic, publisher in robot.pub.items():
            recorder.create_subscription(
                publisher.msg_type,
                topic,
                keep(topic),
                qos.QoSProfile(depth=1000, reliability=qos.ReliabilityPolicy.BEST_EFFORT),
            )
        executor = SingleThreadedExecutor(context, [robot_node, recorder])
        while robot.ticks < seconds * robot.tick_hz:
            executor.spin_once(timeout_sec=1.0)
    finally:
        shutdown(context=context)
    return records


def record_simulation(
    path: str | Path,
    seconds: float,
    storage: str = "mcap",
    seed: int = 0,
    custom_topic: bool = True,
) -> dict[str, int]:
    """Write ``seconds`` of the simulated robot to a rosbag2 at ``path`` (a directory);
    the number of messages per topic."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    typestore.register(get_types_from_msg(CUSTOM_DEFINITION, CUSTOM_TYPE))
    records = simulate(seconds, seed)
    types = {topic: msg._type for topic, _, msg in records}

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    counts: dict[str, int] = {}
    with Writer(Path(path), version=9, storage_plugin=plugin) as writer:
        connections = {
            topic: writer.add_connection(topic, msg_type, typestore=typestore)
            for topic, msg_type in types.items()
        }
        custom = writer.add_connection(CUSTOM_TOPIC, CUSTOM_TYPE, typestore=typestore)
        for topic, stamp_ns, msg in records:
            data = typestore.serialize_cdr(to_rosbags(msg, typestore), msg._type)
            writer.write(connections[topic], stamp_ns, data)
            counts[topic] = counts.get(topic, 0) + 1
            if custom_topic and topic == "/battery_state":
                widget = typestore.types[CUSTOM_TYPE](name="w", level=1.0)
                writer.write(custom, stamp_ns, typestore.serialize_cdr(widget, CUSTOM_TYPE))
                counts[CUSTOM_TOPIC] = counts.get(CUSTOM_TOPIC, 0) + 1
    return counts
