"""Contexts, nodes and timers of the mock rclpy (publishers and subscriptions are in
``endpoints.py``, the executor in ``executor.py``).

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
- An executor runs only what a node's callback groups allow (``callback_groups.py``),
  and every node offers the parameter services, answered only while an executor spins
  it; ``create_service`` and ``create_client`` (``~/name`` expands to the node's fully
  qualified name) work the same way, a client's future done only once an executor
  spins the client's node too (``services.py``); node loggers publish to ``/rosout``,
  as rcl does.
"""

from __future__ import annotations

import copy
import itertools
import threading
from collections.abc import Callable
from typing import Any

from phytrace_edge.sim.mock_ros.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from phytrace_edge.sim.mock_ros.clock import (
    Clock,
    ClockType,
    RealTimeSource,
    TimeSource,
    VirtualTimeSource,
)
from phytrace_edge.sim.mock_ros.endpoints import (
    Publisher,
    Subscription,
    SubscriptionEventCallbacks,
    TopicEndpointInfo,
    type_name_of,
)
from phytrace_edge.sim.mock_ros.messages import Message
from phytrace_edge.sim.mock_ros.parameters import Parameters, overrides_from_arguments
from phytrace_edge.sim.mock_ros.qos import (
    QoSProfile,
    as_profile,
)
from phytrace_edge.sim.mock_ros.rosout import NodeLogger
from phytrace_edge.sim.mock_ros.services import Client, Service, parameter_services, typed_handler

# Discovery is not instant in DDS: a new publisher shows in the graph, and its
# messages reach a subscription, only once the two have found each other; what it
# publishes before is lost to that subscription (a volatile one). Nor is it symmetric:
# the publisher's side may match first (its subscription count says 1) while the
# subscription's side does not know the publisher yet. A best-effort subscription
# drops what arrives then; a reliable pair recovers it once both sides have matched.
DISCOVERY_LATENCY_S = 0.05
SUBSCRIPTION_SIDE_LAG_S = 0.1


class Context:
    """One ROS domain: its graph, its time source and the condition executors wait on."""

    def discovered(self, *created_ns: int, lag_ns: int = 0) -> bool:
        """Whether endpoints created at ``created_ns`` have found each other by now
        (``lag_ns`` later: the subscription's side, see SUBSCRIPTION_SIDE_LAG_S)."""
        now = self.time_source.steady_ns()
        return now >= max(created_ns) + self.discovery_latency_ns + lag_ns

    def __init__(
        self,
        *,
        virtual_time: bool = False,
        start_system_ns: int | None = None,
        discovery_latency_s: float = DISCOVERY_LATENCY_S,
        subscription_side_lag_s: float = SUBSCRIPTION_SIDE_LAG_S,
    ) -> None:
        self.time_source: TimeSource = (
            VirtualTimeSource(start_system_ns) if virtual_time else RealTimeSource()
        )
        self.discovery_latency_ns = int(discovery_latency_s * 1e9)
        self.subscription_side_lag_ns = int(subscription_side_lag_s * 1e9)
        self.condition = threading.Condition()
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.nodes: list[Node] = []
        self.arguments: list[str] = []  # the process's, for --ros-args parameter overrides
        self._ok = False

    def init(self, args: list[str] | None = None) -> None:
        if args is not None:
            self.arguments = list(args)
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


def init(
    args: list[str] | None = None,
    *,
    context: Context | None = None,
    signal_handler_options: Any = None,
) -> None:
    """``rclpy.init``; pass ``Context(virtual_time=True)`` to simulate time. The mock
    installs no signal handlers, whatever ``signal_handler_options`` says."""
    global _default_context
    if context is not None:
        _default_context = context
    _default_context.init(args)


def shutdown(*, context: Context | None = None) -> None:
    (context or _default_context).shutdown()


def try_shutdown(*, context: Context | None = None) -> None:
    """``rclpy.try_shutdown``: shut down unless already shut down."""
    if (context or _default_context).ok():
        shutdown(context=context)


_TIMERS_MADE = itertools.count()


class Timer:
    def __init__(
        self,
        period_ns: int,
        callback: Callable[[], None],
        clock: Clock,
        source: TimeSource,
        callback_group: CallbackGroup,
    ):
        self.period_ns, self.callback, self.clock = period_ns, callback, clock
        self.callback_group = callback_group
        self.sequence = next(_TIMERS_MADE)
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
    """``rclpy.node.Node`` with publishers, subscriptions, timers, parameters (and their
    services), a logger and the graph API."""

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
        self._name, self._namespace = node_name, namespace
        super().__init__(
            overrides_from_arguments(self.context.arguments, self.get_fully_qualified_name())
        )
        self.default_callback_group = MutuallyExclusiveCallbackGroup()
        self.timers: list[Timer] = []
        self.subscriptions: list[Subscription] = []
        self.publishers: list[Publisher] = []
        self.services: list[Service] = parameter_services(self, self.default_callback_group)
        self.clients: list[Client] = []
        self._logger = NodeLogger(self)
        with self.context.condition:
            self.context.nodes.append(self)
            self.context.condition.notify_all()  # clients wait for services to appear

    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return f"{self._namespace.rstrip('/')}/{self._name}"

    def get_logger(self) -> NodeLogger:
        return self._logger

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        with self.context.condition:
            return [(n.get_name(), n.get_namespace()) for n in self.context.nodes]

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
        callback_group: CallbackGroup | None = None,
        event_callbacks: SubscriptionEventCallbacks | None = None,
    ) -> Subscription:
        subscription = Subscription(
            self,
            msg_type,
            topic,
            callback,
            as_profile(qos_profile),
            event_callbacks,
            callback_group or self.default_callback_group,
        )
        with self.context.condition:
            subscription.match_existing(self.context.publishers)
            self.context.subscriptions.append(subscription)
        self.subscriptions.append(subscription)
        return subscription

    def create_timer(
        self,
        timer_period_sec: float,
        callback: Callable[[], None],
        callback_group: CallbackGroup | None = None,
        clock: Clock | None = None,
    ) -> Timer:
        timer = Timer(
            int(timer_period_sec * 1e9),
            callback,
            clock or self.get_clock(),
            self.context.time_source,
            callback_group or self.default_callback_group,
        )
        self.timers.append(timer)
        return timer

    def resolve_service_name(self, service: str, *, only_expand: bool = False) -> str:
        """``~/x`` -> the node's fully qualified name + ``/x``, ``x`` -> under the
        namespace, ``/x`` as it is (rcl's expansion; the mock has no remapping)."""
        if service == "~" or service.startswith("~/"):
            return self.get_fully_qualified_name() + service[1:]
        if service.startswith("/"):
            return service
        return f"{self._namespace.rstrip('/')}/{service}"

    def create_service(
        self,
        srv_type: Any,
        srv_name: str,
        callback: Callable[[Any, Any], Any],
        *,
        qos_profile: QoSProfile | None = None,
        callback_group: CallbackGroup | None = None,
    ) -> Service:
        """Offer ``srv_name``: ``callback(request, response)`` returns the response,
        run by the executor that spins this node."""
        service = Service(
            self.resolve_service_name(srv_name),
            typed_handler(srv_type, callback),
            callback_group or self.default_callback_group,
            srv_type=srv_type,
            srv_name=srv_name,
        )
        with self.context.condition:
            self.services.append(service)
            self.context.condition.notify_all()  # clients wait for services to appear
        return service

    def create_client(
        self,
        srv_type: Any,
        srv_name: str,
        *,
        qos_profile: QoSProfile | None = None,
        callback_group: CallbackGroup | None = None,
    ) -> Client:
        client = Client(
            self,
            srv_type,
            srv_name,
            self.resolve_service_name(srv_name),
            callback_group or self.default_callback_group,
        )
        with self.context.condition:
            self.clients.append(client)
        return client

    def destroy_service(self, service: Service) -> bool:
        with self.context.condition:
            if service in self.services:
                self.services.remove(service)
                return True
        return False

    def destroy_client(self, client: Client) -> bool:
        with self.context.condition:
            client.destroyed = True
            if client in self.clients:
                self.clients.remove(client)
                return True
        return False

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
        for client in list(self.clients):
            self.destroy_client(client)
        self.services.clear()
        with self.context.condition:
            if self in self.context.nodes:
                self.context.nodes.remove(self)

    def get_publishers_info_by_topic(self, topic_name: str) -> list[TopicEndpointInfo]:
        with self.context.condition:
            return [
                TopicEndpointInfo(
                    p.node.get_name(),
                    p.node.get_namespace(),
                    type_name_of(p.msg_type),
                    copy.copy(p.qos_profile),
                )
                for p in self.context.publishers
                if p.topic_name == topic_name and self.context.discovered(p.created_ns)
            ]


def create_node(node_name: str, **kwargs: Any) -> Node:
    return Node(node_name, **kwargs)
