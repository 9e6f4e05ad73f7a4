"""A faithful stand-in for rclpy, for the simulator and the tests (rclpy is not on PyPI).

``messages`` has the ten topics' message classes with rclpy's field types, ``qos`` the
profiles and the compatibility rule, ``clock`` the clocks (real or virtual time) and
``runtime`` nodes, publishers, subscriptions, timers and the executor. It depends on
nothing of the bridge: ``ingest/sources/sim.py`` adapts it to the bridge's ``RosApi``.
"""

from __future__ import annotations

from phytrace_edge.sim.mock_ros import qos
from phytrace_edge.sim.mock_ros.clock import Clock, ClockType
from phytrace_edge.sim.mock_ros.executor import SingleThreadedExecutor
from phytrace_edge.sim.mock_ros.messages import message_type
from phytrace_edge.sim.mock_ros.parameters import ParameterDescriptor
from phytrace_edge.sim.mock_ros.runtime import (
    Context,
    Node,
    SubscriptionEventCallbacks,
    create_node,
    init,
    shutdown,
)

__all__ = [
    "Clock",
    "ClockType",
    "Context",
    "Node",
    "ParameterDescriptor",
    "SingleThreadedExecutor",
    "SubscriptionEventCallbacks",
    "create_node",
    "init",
    "message_type",
    "qos",
    "shutdown",
]
