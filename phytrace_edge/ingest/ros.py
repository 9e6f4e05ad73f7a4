"""The rclpy side of ingest: subscriptions that feed the dispatcher, and the sample timer.

Everything rclpy-specific goes through ``RosApi``, so this code runs unchanged on real
rclpy (``load_rclpy()``, imported lazily: rclpy is not on PyPI and the core must work
without it) and on the mock layer the simulator and the tests use.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

SAMPLED_QUEUE_DEPTH = 5
EVERY_MESSAGE_QUEUE_DEPTH = 100


@dataclass(frozen=True)
class RosApi:
    """The parts of rclpy the bridge uses."""

    create_node: Callable[..., Any]
    message_type: Callable[[str], type]
    qos: Any  # the rclpy.qos module: QoSProfile and the policy enums
    clock: Callable[[str], Any]  # "steady" or "system" -> an rclpy Clock


def load_rclpy() -> RosApi:
    """The real rclpy; raises ImportError when ROS 2 is not sourced."""
    rclpy = importlib.import_module("rclpy")
    qos = importlib.import_module("rclpy.qos")
    clock = importlib.import_module("rclpy.clock")

    def message_type(type_name: str) -> type:
        package, _, name = type_name.split("/")
        return getattr(importlib.import_module(f"{package}.msg"), name)

    def make_clock(kind: str) -> Any:
        clock_type = (
            clock.ClockType.STEADY_TIME if kind == "steady" else clock.ClockType.SYSTEM_TIME
        )
        return clock.Clock(clock_type=clock_type)

    return RosApi(rclpy.create_node, message_type, qos, make_clock)


class NodeClock:
    """The builder's clock read from ROS clocks (so simulated time is honoured)."""

    def __init__(self, api: RosApi) -> None:
        self._steady = api.clock("steady")
        self._system = api.clock("system")

    def monotonic(self) -> float:
        return float(self._steady.now().nanoseconds) / 1e9

    def wall(self) -> float:
        return float(self._system.now().nanoseconds) / 1e9


def subscription_qos(api: RosApi, topic: str) -> Any:
    """A QoS that receives from any publisher: best effort for state streams; reliable
    with a deep queue for topics where every message counts."""
    qos = api.qos
    if TOPIC_BY_NAME[topic].every_message:
        return qos.QoSProfile(
            depth=EVERY_MESSAGE_QUEUE_DEPTH, reliability=qos.ReliabilityPolicy.RELIABLE
        )
    return qos.QoSProfile(depth=SAMPLED_QUEUE_DEPTH, reliability=qos.ReliabilityPolicy.BEST_EFFORT)


def subscribe_topics(
    api: RosApi, node: Any, topics: dict[str, str], dispatcher: Dispatcher
) -> list[Any]:
    """Subscribe ``node`` to ``topics`` (canonical name -> name on the robot)."""
    subscriptions = []
    for canonical, actual in topics.items():
        spec = TOPIC_BY_NAME[canonical]

        def callback(msg: Any, topic: str = canonical) -> None:
            dispatcher.on_message(topic, msg)

        subscriptions.append(
            node.create_subscription(
                api.message_type(spec.type_name), actual, callback, subscription_qos(api, canonical)
            )
        )
    return subscriptions


def create_sample_timer(api: RosApi, node: Any, rate_hz: float, on_tick: Callable[[], None]) -> Any:
    """The builder's tick, on the steady clock: wall-clock jumps and sim time never
    stretch or squeeze the sample rate."""
    return node.create_timer(1.0 / rate_hz, on_tick, clock=api.clock("steady"))
