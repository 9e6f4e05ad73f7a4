"""A faithful stand-in for rclpy, for the simulator and the tests (rclpy is not on PyPI).

``messages`` has the ten topics' message classes with rclpy's field types, ``qos`` the
profiles and the compatibility rule, ``clock`` the clocks (real or virtual time) and
``runtime`` nodes, publishers, subscriptions, timers and the executor.
``ros_api(context)`` packages it as the ``RosApi`` the bridge's ROS code runs on.
"""

from __future__ import annotations

from phytrace_edge.ingest.ros import RosApi
from phytrace_edge.sim.mock_ros import qos
from phytrace_edge.sim.mock_ros.clock import Clock, ClockType
from phytrace_edge.sim.mock_ros.messages import message_type
from phytrace_edge.sim.mock_ros.runtime import (
    Context,
    Node,
    SingleThreadedExecutor,
    SubscriptionEventCallbacks,
    create_node,
    init,
    ok,
    shutdown,
    spin,
    spin_once,
)


def ros_api(context: Context) -> RosApi:
    """The mock as a ``RosApi`` whose nodes and clocks live in ``context``."""

    def make_node(name: str, **kwargs: object) -> Node:
        return create_node(name, context=context, **kwargs)

    def make_clock(kind: str) -> Clock:
        kind_type = ClockType.STEADY_TIME if kind == "steady" else ClockType.SYSTEM_TIME
        return Clock(clock_type=kind_type, source=context.time_source)

    return RosApi(
        make_node,
        message_type,
        qos,
        make_clock,
        lambda on_incompatible: SubscriptionEventCallbacks(incompatible_qos=on_incompatible),
    )


__all__ = [
    "Clock",
    "ClockType",
    "Context",
    "Node",
    "SingleThreadedExecutor",
    "create_node",
    "init",
    "message_type",
    "ok",
    "qos",
    "ros_api",
    "shutdown",
    "spin",
    "spin_once",
]
