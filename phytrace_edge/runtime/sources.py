"""Where messages come from: a source runs a ROS executor on its own thread and feeds
``emit`` one UDM event per sample tick.

- ``sim``: the simulated delivery robot on the mock rclpy layer, in real time.
- ``ros``: the robot's ROS 2 graph through rclpy (ROS 2 must be sourced).
- ``bag:PATH``: a recorded bag, replayed on its own timeline; the source finishes at
  the end of the bag.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from phytrace_edge.build import UDMBuilder
from phytrace_edge.config import Settings
from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.runtime.ros_node import BridgeNode, identity_of

log = logging.getLogger(__name__)

Emit = Callable[[dict[str, Any]], None]
SPIN_TIMEOUT_S = 0.1


class Ingest(Protocol):
    """What the service reads from a source for status and metrics."""

    @property
    def builder(self) -> UDMBuilder: ...

    @property
    def dispatcher(self) -> Dispatcher: ...


class Source(Protocol):
    @property
    def bridge(self) -> Ingest: ...

    @property
    def finished(self) -> threading.Event:
        """Set when a finite source (a bag) has nothing more to give."""
        ...

    def start(self) -> None: ...

    def stop(self) -> None: ...


class _Spinner:
    """Spins an executor on a thread until stopped."""

    def __init__(self, spin_once: Callable[[float], None], name: str) -> None:
        self._spin_once = spin_once
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._spin_once(SPIN_TIMEOUT_S)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


class SimSource:
    """The simulated delivery robot and the bridge node, in real time."""

    def __init__(self, settings: Settings, emit: Emit, seed: int = 0) -> None:
        self.finished = threading.Event()  # never set: the robot runs until stopped
        from phytrace_edge.sim import mock_ros
        from phytrace_edge.sim.robot import DeliveryRobot
        from phytrace_edge.sim.world import World

        self._context = mock_ros.Context()
        self._shutdown = mock_ros.shutdown
        mock_ros.init(context=self._context)
        api = mock_ros.ros_api(self._context)
        robot_node = api.create_node("delivery_robot")
        robot = DeliveryRobot(robot_node, World.create(seed))
        robot_node.create_timer(1.0 / robot.tick_hz, robot.tick, clock=api.clock("steady"))
        self.bridge = BridgeNode(api, settings, emit)
        executor = mock_ros.SingleThreadedExecutor(self._context, [robot_node, self.bridge.node])
        self._spinner = _Spinner(executor.spin_once, "sim-executor")

    def start(self) -> None:
        self._spinner.start()

    def stop(self) -> None:
        self._spinner.stop()
        self._shutdown(context=self._context)


class RosSource:
    """The robot's ROS 2 graph through rclpy."""

    def __init__(self, settings: Settings, emit: Emit, ros_args: list[str]) -> None:
        self.finished = threading.Event()  # never set: the robot runs until stopped
        from phytrace_edge.ingest.ros import load_rclpy

        try:
            api = load_rclpy()
            import rclpy
            from rclpy.executors import SingleThreadedExecutor
        except ImportError:
            raise ConfigError(
                "BRIDGE_INPUT='ros': rclpy is not importable - source ROS 2 first "
                "(source /opt/ros/jazzy/setup.bash), or use --bridge-input dds, sim or bag:PATH"
            ) from None
        self._rclpy = rclpy
        rclpy.init(args=["phytrace-edge", *ros_args])  # remaps, log levels, ...
        self.bridge = BridgeNode(api, settings, emit)
        executor = SingleThreadedExecutor()
        executor.add_node(self.bridge.node)
        self._spinner = _Spinner(lambda t: executor.spin_once(timeout_sec=t), "ros-executor")

    def start(self) -> None:
        self._spinner.start()

    def stop(self) -> None:
        self._spinner.stop()
        self.bridge.node.destroy_node()
        self._rclpy.try_shutdown()


@dataclass
class Ingested:
    """The builder and dispatcher of a source without a ROS node (bag, DDS)."""

    builder: UDMBuilder
    dispatcher: Dispatcher


class BagSource:
    """A recorded bag through the handlers and the builder, on the bag's timeline."""

    def __init__(self, settings: Settings, emit: Emit) -> None:
        from phytrace_edge.ingest.bag import BagClock, open_reader

        self.path = settings.bridge_input.removeprefix("bag:")
        open_reader(self.path).close()  # a missing or unreadable bag fails at start
        self._settings = settings
        self._clock = BagClock()
        builder = UDMBuilder(
            identity_of(settings),
            stale_after_s=settings.stale_after_s,
            use_sim_time=settings.use_sim_time,
            clock=self._clock,
        )
        self.bridge = Ingested(builder, Dispatcher(builder.add_reading))
        self._emit = emit
        self._stop = threading.Event()
        self.finished = threading.Event()
        self.summary: Any = None
        self._thread = threading.Thread(target=self._replay, name="bag-replay", daemon=True)

    def _replay(self) -> None:
        from phytrace_edge.ingest.bag import replay

        s = self._settings
        try:
            self.summary = replay(
                self.path,
                s.topics,
                self.bridge.dispatcher.on_message,
                lambda at: self._emit(self.bridge.builder.build_event(captured_at_s=at)),
                self._clock,
                s.sample_rate_hz,
                s.replay_rate,
                self._stop,
            )
            log.info("%s", self.summary.describe())
        finally:
            self.finished.set()

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)


class DdsSource:
    """A ROS 2 robot heard over Cyclone DDS, without ROS; events at SAMPLE_RATE_HZ."""

    def __init__(self, settings: Settings, emit: Emit) -> None:
        from phytrace_edge.ingest.dds import DdsReaders

        self.finished = threading.Event()  # never set: the robot runs until stopped
        builder = UDMBuilder(
            identity_of(settings),
            stale_after_s=settings.stale_after_s,
            use_sim_time=settings.use_sim_time,
        )
        self.bridge = Ingested(builder, Dispatcher(builder.add_reading))
        self._readers = DdsReaders(settings.topics, self.bridge.dispatcher.on_message, os.environ)
        self._period = 1.0 / settings.sample_rate_hz
        self._emit = emit
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, name="dds-sampler", daemon=True)

    def _tick(self) -> None:
        """One event per period on the monotonic clock, without drift."""
        next_at = time.monotonic() + self._period
        while not self._stop.wait(max(0.0, next_at - time.monotonic())):
            self._readers.take_latest()  # the newest sample of each state topic
            self._emit(self.bridge.builder.build_event())
            next_at += self._period

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._readers.close()


def make_source(settings: Settings, emit: Emit, ros_args: list[str]) -> Source:
    """The source BRIDGE_INPUT names; ``ros_args`` (``--ros-args ...``) go to rclpy."""
    kind = settings.bridge_input
    if kind == "sim":
        return SimSource(settings, emit)
    if kind == "ros":
        return RosSource(settings, emit, ros_args)
    if kind == "dds":
        return DdsSource(settings, emit)
    if kind.startswith("bag:"):
        return BagSource(settings, emit)
    raise ConfigError(f"BRIDGE_INPUT={kind!r}: must be ros, dds, sim or bag:PATH")
