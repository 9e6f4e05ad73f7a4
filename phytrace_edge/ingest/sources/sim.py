"""``BRIDGE_INPUT=sim``: the simulated delivery robot on the mock rclpy layer.

The robot node and the bridge's subscriptions share one mock ROS context and go
through the same ``ros_graph`` code as real rclpy. In real time (``phytrace-edge run``)
the sampler ticks on its own thread; in virtual time (``run_simulation``) the source
keeps time and ticks from a mock timer, so 100 robot cycles take a fraction of a second.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

from phytrace_edge.ingest.generic import rosidl_field_types
from phytrace_edge.ingest.sources.base import NODE_NAME, Feed, Finished, SourceOptions
from phytrace_edge.ingest.sources.ros import load_rclpy
from phytrace_edge.ingest.sources.ros_graph import (
    NodeClock,
    RosApi,
    TopicSubscriber,
    declare_settings,
    subscribe_topics,
    wanted_topics,
)
from phytrace_edge.sim import mock_ros
from phytrace_edge.sim.mock_ros import as_rclpy
from phytrace_edge.sim.robot import DeliveryRobot
from phytrace_edge.sim.world import World

SPIN_TIMEOUT_S = 0.1


def mock_api(context: mock_ros.Context) -> RosApi:
    """The mock rclpy as a ``RosApi`` whose nodes and clocks live in ``context``: the
    same ``load_rclpy`` as the ``ros`` input, over the mock's modules."""
    return load_rclpy(as_rclpy.modules(context).__getitem__)


class SimSource:
    """The simulated robot and the bridge's subscriptions to it."""

    def __init__(self, options: SourceOptions) -> None:
        self._options = options
        self.keeps_time = options.virtual_time
        self._context = mock_ros.Context(virtual_time=options.virtual_time)
        mock_ros.init(context=self._context)
        self._api = mock_api(self._context)
        self.clock = NodeClock(self._api) if options.virtual_time else None
        self.robot: DeliveryRobot | None = None
        self._subscriber: TopicSubscriber | None = None
        self._executor: mock_ros.SingleThreadedExecutor | None = None

    def start(self, feed: Feed) -> None:
        api, steady = self._api, self._api.clock("steady")
        robot_node = api.create_node("delivery_robot")
        self.robot = DeliveryRobot(robot_node, World.create(self._options.seed))
        robot_node.create_timer(1.0 / self.robot.tick_hz, self.robot.tick, clock=steady)
        node = api.create_node(NODE_NAME)
        declare_settings(api, node, dict(self._options.parameters))
        self._subscriber = subscribe_topics(
            api,
            node,
            wanted_topics(dict(self._options.topics), dict(self._options.extra_topics)),
            feed.on_message,
            dict(self._options.qos_overrides),
        )
        if self.keeps_time:
            node.create_timer(feed.sample_period_s, lambda: feed.tick(None), clock=steady)
        self._executor = mock_ros.SingleThreadedExecutor(self._context, [robot_node, node])

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Spin the robot and the subscriptions until stopped (or, in virtual time,
        until the robot has run ``max_ticks`` cycles)."""
        assert self._executor is not None and self.robot is not None, "start() first"
        limit = self._options.max_ticks
        while not stop.is_set() and self._context.ok():
            if limit is not None and self.robot.ticks >= limit:
                return
            self._executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            beat()

    def field_types(self, msg: Any) -> Mapping[str, str]:
        return rosidl_field_types(msg)

    def before_tick(self) -> None:
        """Messages arrive through callbacks: nothing to take at the tick."""

    def stop(self) -> None:
        mock_ros.shutdown(context=self._context)

    def finished(self) -> Finished | None:
        return None

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        return self._subscriber.stats() if self._subscriber else {}
