"""``BRIDGE_INPUT=sim``: the simulated delivery robot, heard by the ``ros`` input.

The robot is a node on a mock ROS graph of its own (no process-wide state), and the
bridge's side is ``RosSource`` itself over the mock's rclpy modules: the same node,
parameters, QoS matching and state streams taken at the tick as on a real robot. In
real time (``phytrace-edge run``) the sampler ticks on its own thread; in virtual time
(``run_simulation``) the source keeps time and ticks from a mock timer, so 100 robot
cycles take a fraction of a second.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from phytrace_edge.ingest.dispatch import Take
from phytrace_edge.ingest.sources.base import Feed, Finished, SourceOptions
from phytrace_edge.ingest.sources.ros import RosSource
from phytrace_edge.ingest.sources.ros_graph import NodeClock
from phytrace_edge.sim import mock_ros
from phytrace_edge.sim.mock_ros import as_rclpy
from phytrace_edge.sim.robot import DeliveryRobot
from phytrace_edge.sim.world import World


class SimSource:
    """The simulated robot, and the ``ros`` input subscribed to it."""

    def __init__(self, options: SourceOptions) -> None:
        self._options = options
        self.keeps_time = options.virtual_time
        self._context = mock_ros.Context(virtual_time=options.virtual_time)
        self._modules = as_rclpy.modules(self._context)
        self._ros = RosSource(options, import_module=self._modules.__getitem__)
        self.clock = NodeClock(self._ros.api) if options.virtual_time else None
        self.robot: DeliveryRobot | None = None

    def start(self, feed: Feed) -> None:
        """The robot first (a bridge usually joins a running robot), then the bridge's
        node exactly as the ``ros`` input makes it; one executor spins both."""
        self._modules["rclpy"].init()
        api, steady = self._ros.api, self._ros.api.clock("steady")
        robot_node = api.create_node("delivery_robot")
        self.robot = DeliveryRobot(robot_node, World.create(self._options.seed))
        robot_node.create_timer(1.0 / self.robot.tick_hz, self.robot.tick, clock=steady)
        self._ros.start(feed)
        self._ros.executor.add_node(robot_node)
        if self.keeps_time:
            self._ros.node.create_timer(feed.sample_period_s, lambda: feed.tick(None), clock=steady)

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Spin the robot and the bridge's node until stopped (or, in virtual time,
        until the robot has run ``max_ticks`` cycles)."""
        assert self.robot is not None, "start() first"
        limit = self._options.max_ticks
        while not stop.is_set() and self._context.ok():
            if limit is not None and self.robot.ticks >= limit:
                return
            self._ros.executor.spin_once(timeout_sec=0.1)
            beat()

    def field_types(self, msg: Any) -> Mapping[str, str]:
        return self._ros.field_types(msg)

    def before_tick(self) -> Sequence[Take]:
        return self._ros.before_tick()

    def stop(self) -> None:
        self._ros.stop()

    def finished(self) -> Finished | None:
        return None

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        return self._ros.topic_stats()
