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
import functools
import itertools
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from phytrace_edge.sim.mock_ros.clock import (
    Clock,
    ClockType,
    RealTimeSource,
    TimeSource,
    VirtualTimeSource,
)
from phytrace_edge.sim.mock_ros.messages import Message, wire_copy
from phytrace_edge.sim.mock_ros.qos import (
    QoSPolicyKind,
    QoSProfile,
    as_profile,
    incompatible_policy,
)


class Context:
    """One ROS domain: its graph, its time source and the condition executors wait on."""

    def __init__(self, *, virtual_time: bool = False, start_system_ns: int | None = None) -> None:
        self.time_source: TimeSource = (
            VirtualTimeSource(start_system_ns) if virtual_time else RealTimeSource()
        )
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


def ok(*, context: Context | None = None) -> bool:
    return (context or _default_context).ok()


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

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"Expected {self.msg_type.__name__}, got {type(msg).__name__}")
        context = self.node.context
        with context.condition:
            if self.qos_profile.durability.name == "TRANSIENT_LOCAL":
                self._history.append(wire_copy(msg))
            for subscription in context.subscriptions:
                if subscription.matches_topic(self):
                    subscription.offer(self, msg)
            context.condition.notify_all()

    def get_subscription_count(self) -> int:
        with self.node.context.condition:
            return sum(
                1
                for s in self.node.context.subscriptions
                if s.matches_topic(self)
                and incompatible_policy(self.qos_profile, s.qos_profile) is None
            )


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


@dataclass
class Parameter:
    name: str
    value: Any = None


class _Logger:
    def __init__(self, name: str) -> None:
        import logging

        self._log = logging.getLogger(f"mock_ros.{name}")

    def info(self, msg: str) -> None:
        self._log.info(msg)

    def warning(self, msg: str) -> None:
        self._log.warning(msg)

    warn = warning

    def error(self, msg: str) -> None:
        self._log.error(msg)

    def debug(self, msg: str) -> None:
        self._log.debug(msg)


class Node:
    """``rclpy.node.Node`` with publishers, subscriptions, timers, parameters, graph."""

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str = "/",
        context: Context | None = None,
        parameter_overrides: list[Parameter] | None = None,
        automatically_declare_parameters_from_overrides: bool = False,
    ) -> None:
        self.context = context or _default_context
        if not self.context.ok():
            raise RuntimeError("rclpy.init() has not been called")
        self._name, self._namespace = node_name, namespace
        self._overrides = {p.name: p.value for p in parameter_overrides or []}
        self._parameters: dict[str, Parameter] = {}
        if automatically_declare_parameters_from_overrides:
            self._parameters = {k: Parameter(k, v) for k, v in self._overrides.items()}
        self.timers: list[Timer] = []
        self.subscriptions: list[Subscription] = []
        self.publishers: list[Publisher] = []
        with self.context.condition:
            self.context.nodes.append(self)

    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_logger(self) -> _Logger:
        return _Logger(self._name)

    def get_clock(self) -> Clock:
        return Clock(clock_type=ClockType.ROS_TIME, source=self.context.time_source)

    def declare_parameter(self, name: str, value: Any = None) -> Parameter:
        parameter = Parameter(name, self._overrides.get(name, value))
        self._parameters[name] = parameter
        return parameter

    def get_parameter(self, name: str) -> Parameter:
        return self._parameters[name]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

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

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        with self.context.condition:
            endpoints: list[Publisher | Subscription] = [
                *self.context.publishers,
                *self.context.subscriptions,
            ]
            topics: dict[str, set[str]] = {}
            for endpoint in endpoints:
                topics.setdefault(endpoint.topic_name, set()).add(_type_name(endpoint.msg_type))
        return sorted((name, sorted(types)) for name, types in topics.items())

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
                if p.topic_name == topic_name
            ]

    def count_publishers(self, topic_name: str) -> int:
        return len(self.get_publishers_info_by_topic(topic_name))


def create_node(node_name: str, **kwargs: Any) -> Node:
    return Node(node_name, **kwargs)


@dataclass
class SingleThreadedExecutor:
    """Runs one ready callback per ``spin_once``, oldest work first."""

    context: Context = field(default_factory=default_context)
    nodes: list[Node] = field(default_factory=list)
    _turn: itertools.count = field(default_factory=itertools.count)

    def add_node(self, node: Node) -> bool:
        if node not in self.nodes:
            self.nodes.append(node)
        return True

    def remove_node(self, node: Node) -> None:
        if node in self.nodes:
            self.nodes.remove(node)

    def spin_once(self, timeout_sec: float | None = None) -> None:
        source = self.context.time_source
        deadline = None if timeout_sec is None else source.steady_ns() + int(timeout_sec * 1e9)
        with self.context.condition:
            while self.context.ok():
                work = self._ready_work()
                if work is not None:
                    break
                wake = self._next_timer_ns()
                if deadline is not None:
                    wake = deadline if wake is None else min(wake, deadline)
                if wake is None and source.virtual:
                    return  # virtual time with nothing scheduled: nothing can ever happen
                if deadline is not None and source.steady_ns() >= deadline:
                    return
                source.wait(self.context.condition, wake)
            else:
                return
        work()

    def spin(self) -> None:
        while self.context.ok() and self.nodes:
            self.spin_once(timeout_sec=0.1)

    def _ready_work(self) -> Callable[[], None] | None:
        """The next callback to run, or None (caller holds the condition)."""
        for node in self.nodes:
            for subscription in node.subscriptions:
                if subscription.pending_events and subscription.event_callbacks.incompatible_qos:
                    event = subscription.pending_events.pop(0)
                    callback = subscription.event_callbacks.incompatible_qos
                    return functools.partial(callback, event)
            ready = [s for s in node.subscriptions if s.pending]
            if ready:
                subscription = ready[next(self._turn) % len(ready)]
                msg = subscription.pending.popleft()
                return functools.partial(subscription.callback, msg)
        for node in self.nodes:
            for timer in node.timers:
                if timer.is_ready():
                    return timer.fire
        return None

    def _next_timer_ns(self) -> int | None:
        calls = [t.next_call_ns for n in self.nodes for t in n.timers if not t.cancelled]
        return min(calls) if calls else None


def spin_once(node: Node, *, timeout_sec: float | None = None) -> None:
    executor = SingleThreadedExecutor(node.context, [node])
    executor.spin_once(timeout_sec)


def spin(node: Node) -> None:
    SingleThreadedExecutor(node.context, [node]).spin()
