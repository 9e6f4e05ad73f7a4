"""``BRIDGE_INPUT=ros``: the robot's ROS 2 graph through rclpy, the one module that
imports it (lazily: rclpy comes with ROS 2 or its wheels, and the core runs without).

One node, ``phytrace_edge``: its executor runs the callbacks of the topics where every
message counts as it comes (diagnostics, goals, an incident's trigger topics), the
graph checks, the parameter services and the ``~/mark`` service
(``std_srvs/srv/Trigger``: an incident marked by hand); the state streams are taken at
the sample tick (``ros_graph.taken_at_the_tick``): the newest message of each, and
every message of an incident's window topics, while recording.
"""

from __future__ import annotations

import importlib
import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from types import ModuleType
from typing import Any

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import Take
from phytrace_edge.ingest.generic import rosidl_field_types
from phytrace_edge.ingest.sources.base import (
    NODE_NAME,
    Feed,
    Finished,
    MarkReply,
    SourceOptions,
)
from phytrace_edge.ingest.sources.ros_graph import (
    RosApi,
    Taken,
    TopicSubscriber,
    declare_settings,
    subscribe_topics,
    wanted_topics,
)

log = logging.getLogger(__name__)

SPIN_TIMEOUT_S = 0.1
MARK_SERVICE = "~/mark"  # /phytrace_edge/mark, under the node's namespace
MARK_SERVICE_REASON = "~/mark service call"  # a Trigger request carries no reason


def load_rclpy(import_module: Callable[[str], ModuleType] = importlib.import_module) -> RosApi:
    """rclpy as a ``RosApi``; raises ImportError when ROS 2 is not sourced.
    ``import_module`` finds its modules: the real ones, or the mock's
    (``sim.mock_ros.as_rclpy``), so both go through this same code."""
    rclpy = import_module("rclpy")
    qos = import_module("rclpy.qos")
    clock = import_module("rclpy.clock")

    def message_type(type_name: str) -> type:
        package, _, name = type_name.split("/")
        message_class: type = getattr(import_module(f"{package}.msg"), name)
        return message_class

    def make_clock(kind: str) -> Any:
        clock_type = (
            clock.ClockType.STEADY_TIME if kind == "steady" else clock.ClockType.SYSTEM_TIME
        )
        return clock.Clock(clock_type=clock_type)

    try:  # Iron and later
        events = import_module("rclpy.event_handler")
    except ImportError:  # Humble
        events = import_module("rclpy.qos_event")

    def subscription_events(on_incompatible: Callable[[Any], None]) -> Any:
        return events.SubscriptionEventCallbacks(incompatible_qos=on_incompatible)

    def take(subscription: Any) -> Taken | None:
        """The newest message waiting on a subscription no executor runs (what the
        executor itself does before it calls a callback), or None."""
        with subscription.handle:
            taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        return None if taken is None else Taken(taken[0], received_ns(taken[1]))

    def parameter_descriptor(description: str) -> Any:
        descriptor = import_module("rcl_interfaces.msg").ParameterDescriptor
        return descriptor(description=description, read_only=True, dynamic_typing=True)

    return RosApi(
        rclpy.create_node,
        message_type,
        qos,
        make_clock,
        subscription_events,
        take,
        parameter_descriptor,
        import_module("rclpy.callback_groups").CallbackGroup,
    )


def received_ns(info: Mapping[str, Any]) -> int:
    """When the middleware received a message, from the MessageInfo rclpy's take gives
    (ns on the system clock): ``received_timestamp`` (Fast DDS fills it in), else the
    writer's ``source_timestamp`` (rmw_cyclonedds_cpp gives 0 for the reception: Cyclone
    does not say), else 0, unknown."""
    return int(info.get("received_timestamp") or info.get("source_timestamp") or 0)


def import_error_message(exc: ImportError) -> str:
    """What to do about rclpy failing to import: ROS 2 not sourced, or (the import
    itself says so) something rclpy needs is missing from this Python."""
    if exc.name in ("rclpy", None) and "rclpy" in str(exc):
        return (
            "BRIDGE_INPUT='ros': rclpy is not importable - source ROS 2 first "
            "(source /opt/ros/jazzy/setup.bash), or use --input dds, sim or bag:PATH"
        )
    return (
        f"BRIDGE_INPUT='ros': rclpy did not import ({type(exc).__name__}: {exc}) - ROS 2 is "
        "sourced, but this Python lacks what rclpy needs: run the bridge with the "
        "distribution's python3, or a venv made with --system-site-packages (and pip "
        "install what the message names)"
    )


class RosSource:
    """Subscriptions to the robot's topics on an rclpy node, spun on the ingest thread.

    ``import_module`` finds rclpy: the real one, or the mock's modules, over which the
    simulator (``sources/sim.py``) runs this same input."""

    keeps_time = False
    clock = None

    def __init__(
        self,
        options: SourceOptions,
        import_module: Callable[[str], ModuleType] = importlib.import_module,
    ) -> None:
        self._options = options
        self._import = import_module
        try:
            self.api = load_rclpy(import_module)
            self._rclpy = import_module("rclpy")
            self._executors = import_module("rclpy.executors")
        except ImportError as exc:
            raise ConfigError(import_error_message(exc)) from None
        self.node: Any = None
        self.executor: Any = None
        self.subscriber: TopicSubscriber | None = None  # once started
        self.mark_service: Any = None  # once started, when the feed takes marks

    def start(self, feed: Feed) -> None:
        ros_args = self._options.ros_args
        # the bridge owns SIGINT and SIGTERM: it stops ingest, then the queue, then
        # ship, in order; rclpy's own handlers would shut the context down under the
        # executor (ExternalShutdownException on every stop)
        signals = self._import("rclpy.signals")
        self._rclpy.init(
            args=["phytrace-edge", *(("--ros-args", *ros_args) if ros_args else ())],
            signal_handler_options=signals.SignalHandlerOptions.NO,
        )
        self.node = self.api.create_node(NODE_NAME)
        declare_settings(self.api, self.node, dict(self._options.parameters))
        # state streams (odometry, IMU, scan, ...) are taken at the sample tick: no
        # Python callback for each of their messages
        self.subscriber = subscribe_topics(
            self.api,
            self.node,
            wanted_topics(
                dict(self._options.topics),
                dict(self._options.extra_topics),
                self._options.every_message,
                self._options.full_rate,
            ),
            feed.on_message,
            dict(self._options.qos_overrides),
            take_at_tick=True,
            due=feed.due,
        )
        if feed.mark is not None:
            self.mark_service = self._serve_marks(feed.mark)
        self.executor = self._executors.SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def _serve_marks(self, mark: Callable[[str], MarkReply]) -> Any:
        """``~/mark`` (``std_srvs/srv/Trigger``) on the node, answered in the executor's
        thread; None, with one WARNING, when std_srvs is not installed (the bridge runs
        on without it: ``phytrace-edge mark`` still marks)."""
        try:
            trigger = self._import("std_srvs.srv").Trigger
        except ImportError as exc:
            log.warning(
                "no %s service: the ROS package std_srvs does not import (%s: %s); install "
                "it (ros-<distro>-std-srvs from apt, or the ros-std-srvs wheel) for incident "
                "marks over ROS; phytrace-edge mark works without it",
                MARK_SERVICE,
                type(exc).__name__,
                exc,
            )
            return None

        def on_call(request: Any, response: Any) -> Any:
            try:
                reply = mark(MARK_SERVICE_REASON)
            except Exception as exc:  # an exception here would leave the executor
                log.exception("%s failed", MARK_SERVICE)
                reply = MarkReply(False, f"the bridge could not take the mark: {exc}")
            response.success = reply.accepted
            response.message = reply.message
            return response

        return self.node.create_service(trigger, MARK_SERVICE, on_call)

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        while not stop.is_set():
            self.executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            beat()

    def field_types(self, msg: Any) -> Mapping[str, str]:
        return rosidl_field_types(msg)

    def before_tick(self) -> Sequence[Take]:
        """The newest message of each state stream, taken (not called back)."""
        return self.subscriber.take_latest() if self.subscriber is not None else []

    def stop(self) -> None:
        if self.node is not None:
            self.node.destroy_node()
        self._rclpy.try_shutdown()

    def finished(self) -> Finished | None:
        return None

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        return self.subscriber.stats() if self.subscriber else {}
