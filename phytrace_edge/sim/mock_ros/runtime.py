"""Nodes, publishers, subscriptions, timers and the executor of the mock rclpy.

Semantics kept from ROS 2 on DDS, because the bridge's behaviour depends on them:

- ``publish`` delivers a *copy* to every matching subscription; the callback runs
  later, in whichever thread spins the subscribing node.
- Matching needs the same topic name and type and compatible QoS (``qos.py``); an
  incompatible pair delivers nothing and fires the subscription's
  ``incompatible_qos`` event callback.
- KEEP_LAST history keeps the newest ``depth`` messages per subscription.
- A TRANSIENT_LOCAL publisher replays its last ``depth`` messages to a late
  TRANSIENT_LOCAL subscription.
- The graph API (topic names and types, publisher endpoint info with QoS) reflects
  the current publishers, so code that discovers topics and matches QoS can be tested.
"""

from __future__ import annotations

import copy
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from phytrace_edge.sim.mock_ros.clock import (
    Clock,
    ClockType,
    RealTimeSource,
    TimeSource,
    VirtualTimeSource,
)
from phytrace_edge.sim.mock_ros.messages import Message, wire_copy
from phytrace_edge.sim.mock_ros.parameters import Parameters
from phytrace_edge.sim.mock_ros.qos import (
    QoSPolicyKind,
    QoSProfile,
    as_profile,
    incompatible_policy,
)

# Discovery is not instant in DDS: a new publisher shows in the graph, and its
# messages reach a subscription, only once the two have found each other; what it
# publishes before is lost to that subscription (a volatile one).
DISCOVERY_LATENCY_S = 0.05


class Context:
    """One ROS domain: its graph, its time source and the condition executors wait on."""

    def discovered(self, *created_ns: int) -> bool:
        """Whether endpoints created at ``created_ns`` have found each other by now."""
        return self.time_source.steady_ns() >= max(created_ns) + self.discovery_latency_ns

    def __init__(
        self,
        *,
        virtual_time: bool = False,
        start_system_ns: int | None = None,
        discovery_latency_s: float = DISCOVERY_LATENCY_S,
    ) -> None:
        self.time_source: TimeSource = (
            VirtualTimeSource(start_system_ns) if virtual_time else RealTimeSource()
        )
        self.discovery_latency_ns = int(discovery_latency_s * 1e9)
        self.condition = threading.Condition()
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.nodes: list[Node] = []
        self._ok = False

    def init(self) -> None:
        self._ok = True

    def ok(self) -> bool:
        return self._ok

    def shutdown(self) -> None:
        for node in list(self.nodes):
            node.destroy_node()
        self._ok = False
        with self.condition:
            self.condition.notify_all()


_default_context = Context()


def default_context() -> Context:
    return _default_context


def init(args: Any = None, *, context: Context | None = None) -> None:
    """``rclpy.init``; pass ``Context(virtual_time=True)`` to simulate time."""
    global _default_context
    if context is not None:
        _default_context = context
    _default_context.init()


def shutdown(*, context: Context | None = None) -> None:
    (context or _default_context).shutdown()


@dataclass
class QoSRequestedIncompatibleQoSInfo:
    total_count: int = 0
    total_count_change: int = 0
    last_policy_kind: QoSPolicyKind = QoSPolicyKind.INVALID


@dataclass
class SubscriptionEventCallbacks:
    incompatible_qos: Callable[[QoSRequestedIncompatibleQoSInfo], None] | None = None


@dataclass
class TopicEndpointInfo:
    node_name: str
    node_namespace: str
    topic_type: str
    qos_profile: QoSProfile


def _type_name(msg_type: type[Message]) -> str:
    return msg_type._type


class Publisher:
    def __init__(self, node: Node, msg_type: type[Message], topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.qos_profile = node, msg_type, topic, qos
        self._history: deque[Any] = deque(maxlen=qos.depth)
        self.created_ns = node.context.time_source.steady_ns()

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"Expected {self.msg_type.__name__}, got {type(msg).__name__}")
        context = self.node.context
        with context.condition:
            if self.qos_profile.durability.name == "TRANSIENT_LOCAL":
                self._history.append(wire_copy(msg))
            for subscription in context.subscriptions:
                if subscription.matches_topic(self) and context.discovered(
                    self.created_ns, subscription.created_ns
                ):
                    subscription.offer(self, msg)
            context.condition.notify_all()


class Subscription:
    def __init__(
        self,
        node: Node,
        msg_type: type[Message],
        topic: str,
        callback: Callable[[Any], None],
        qos: QoSProfile,
        event_callbacks: SubscriptionEventCallbacks | None,
    ) -> None:
        self.node, self.msg_type, self.topic_name = node, msg_type, topic
        self.callback, self.qos_profile = callback, qos
        self.event_callbacks = event_callbacks or SubscriptionEventCallbacks()
        self.pending: deque[Any] = deque(
            maxlen=qos.depth if qos.history.name == "KEEP_LAST" else None
        )
        self.incompatible = QoSRequestedIncompatibleQoSInfo()
        self.pending_events: list[QoSRequestedIncompatibleQoSInfo] = []
        self._incompatible_with: set[int] = set()
        self.created_ns = node.context.time_source.steady_ns()

    def take(self) -> Any:
        """The oldest message waiting, or None (what rclpy's take_message gives a
        subscription no executor spins)."""
        with self.node.context.condition:
            return self.pending.popleft() if self.pending else None

    def matches_topic(self, publisher: Publisher) -> bool:
        return publisher.topic_name == self.topic_name and _type_name(
            publisher.msg_type
        ) == _type_name(self.msg_type)

    def offer(self, publisher: Publisher, msg: Any) -> None:
        """Deliver ``msg`` if QoS allows (caller holds the context condition)."""
        policy = incompatible_policy(publisher.qos_profile, self.qos_profile)
        if policy is not None:
            self._note_incompatible(publisher, policy)
            return
        self.pending.append(wire_copy(msg))

    def _note_incompatible(self, publisher: Publisher, policy: QoSPolicyKind) -> None:
        if id(publisher) in self._incompatible_with:
            return
        self._incompatible_with.add(id(publisher))
        self.incompatible.total_count += 1
        self.incompatible.last_policy_kind = policy
        self.pending_events.append(
            QoSRequestedIncompatibleQoSInfo(self.incompatible.total_count, 1, policy)
        )

    def match_existing(self, publishers: list[Publisher]) -> None:
        """On creation: note incompatible publishers and take transient-local history."""
        for publisher in publishers:
            if not self.matches_topic(publisher):
                continue
            policy = incompatible_policy(publisher.qos_profile, self.qos_profile)
            if policy is not None:
                self._note_incompatible(publisher, policy)
            elif self.qos_profile.durability.name == "TRANSIENT_LOCAL":
                self.pending.extend(wire_copy(m) for m in publisher._history)


class Timer:
    def __init__(
        self, period_ns: int, callback: Callable[[], None], clock: Clock, source: TimeSource
    ):
        self.period_ns, self.callback, self.clock = period_ns, callback, clock
        self._source = source
        self.next_call_ns = source.steady_ns() + period_ns
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True

    def is_ready(self) -> bool:
        return not self.cancelled and self._source.steady_ns() >= self.next_call_ns

    def fire(self) -> None:
        self.next_call_ns += self.period_ns
        now = self._source.steady_ns()
        if self.next_call_ns <= now:  # fell behind: skip missed periods, as rcl does
            self.next_call_ns = now + self.period_ns
        self.callback()


class Node(Parameters):
    """``rclpy.node.Node`` with publishers, subscriptions, timers, parameters and the
    graph API."""

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str = "/",
        context: Context | None = None,
    ) -> None:
        self.context = context or _default_context
        if not self.context.ok():
            raise RuntimeError("rclpy.init() has not been called")
        super().__init__()
        self._name, self._namespace = node_name, namespace
        self.timers: list[Timer] = []
        self.subscriptions: list[Subscription] = []
        self.publishers: list[Publisher] = []
        with self.context.condition:
            self.context.nodes.append(self)

    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_clock(self) -> Clock:
        return Clock(clock_type=ClockType.ROS_TIME, source=self.context.time_source)

    def create_publisher(
        self, msg_type: type[Message], topic: str, qos_profile: QoSProfile | int
    ) -> Publisher:
        publisher = Publisher(self, msg_type, topic, as_profile(qos_profile))
        with self.context.condition:
            self.context.publishers.append(publisher)
            for subscription in self.context.subscriptions:
                if subscription.matches_topic(publisher):
                    subscription.match_existing([publisher])
        self.publishers.append(publisher)
        return publisher

    def create_subscription(
        self,
        msg_type: type[Message],
        topic: str,
        callback: Callable[[Any], None],
        qos_profile: QoSProfile | int,
        *,
        event_callbacks: SubscriptionEventCallbacks | None = None,
    ) -> Subscription:
        subscription = Subscription(
            self, msg_type, topic, callback, as_profile(qos_profile), event_callbacks
        )
        with self.context.condition:
            subscription.match_existing(self.context.publishers)
            self.context.subscriptions.append(subscription)
        self.subscriptions.append(subscription)
        return subscription

    def create_timer(
        self, timer_period_sec: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> Timer:
        timer = Timer(
            int(timer_period_sec * 1e9),
            callback,
            clock or self.get_clock(),
            self.context.time_source,
        )
        self.timers.append(timer)
        return timer

    def destroy_subscription(self, subscription: Subscription) -> bool:
        with self.context.condition:
            if subscription in self.context.subscriptions:
                self.context.subscriptions.remove(subscription)
        if subscription in self.subscriptions:
            self.subscriptions.remove(subscription)
            return True
        return False

    def destroy_publisher(self, publisher: Publisher) -> bool:
        with self.context.condition:
            if publisher in self.context.publishers:
                self.context.publishers.remove(publisher)
        if publisher in self.publishers:
            self.publishers.remove(publisher)
            return True
        return False

    def destroy_node(self) -> None:
        for subscription in list(self.subscriptions):
            self.destroy_subscription(subscription)
        for publisher in list(self.publishers):
            self.destroy_publisher(publisher)
        for timer in self.timers:
            timer.cancel()
        with self.context.condition:
            if self in self.context.nodes:
                self.context.nodes.remove(self)

    def get_publishers_info_by_topic(self, topic_name: str) -> list[TopicEndpointInfo]:
        with self.context.condition:
            return [
                TopicEndpointInfo(
                    p.node.get_name(),
                    p.node.get_namespace(),
                    _type_name(p.msg_type),
                    copy.copy(p.qos_profile),
                )
                for p in self.context.publishers
                if p.topic_name == topic_name and self.context.discovered(p.created_ns)
            ]


def create_node(node_name: str, **kwargs: Any) -> Node:
    return Node(node_name, **kwargs)
