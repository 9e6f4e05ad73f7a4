"""Publishers and subscriptions of the mock rclpy, and what the graph says of them.

Semantics kept from ROS 2 on DDS (the module ``runtime`` says which and why): a copy
per matching subscription, QoS compatibility with its event, KEEP_LAST history,
transient-local replay, discovery that takes time and is not symmetric; and, as
rclpy's ``take_message`` gives it, the MessageInfo of each message taken (when it was
written and received, on the system clock of the context's time source).
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from phytrace_edge.sim.mock_ros.callback_groups import CallbackGroup
from phytrace_edge.sim.mock_ros.messages import Message, wire_copy
from phytrace_edge.sim.mock_ros.qos import (
    QoSPolicyKind,
    QoSProfile,
    ReliabilityPolicy,
    incompatible_policy,
)

if TYPE_CHECKING:
    from phytrace_edge.sim.mock_ros.runtime import Node


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


def type_name_of(msg_type: type[Message]) -> str:
    return msg_type._type


@dataclass(frozen=True)
class Written:
    """A message as its publisher wrote it: a copy, when, and its sequence number."""

    msg: Any
    source_ns: int
    sequence: int


_PUBLISHERS_MADE = itertools.count(1)


class Publisher:
    def __init__(self, node: Node, msg_type: type[Message], topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.qos_profile = node, msg_type, topic, qos
        self._history: deque[Written] = deque(maxlen=qos.depth)
        self.created_ns = node.context.time_source.steady_ns()
        self.gid = next(_PUBLISHERS_MADE).to_bytes(16, "big")  # rmw's 16-byte gid
        self._written = 0

    def get_subscription_count(self) -> int:
        """Subscriptions matched with this publisher: discovered, of a compatible QoS."""
        context = self.node.context
        with context.condition:
            return sum(
                s.matches_topic(self)
                and context.discovered(self.created_ns, s.created_ns)
                and incompatible_policy(self.qos_profile, s.qos_profile) is None
                for s in context.subscriptions
            )

    def _reaches(self, subscription: Subscription) -> bool:
        """Whether a message published now gets to ``subscription``: both sides have
        matched, or this side has and the pair is reliable (it is resent)."""
        context = self.node.context
        if not context.discovered(self.created_ns, subscription.created_ns):
            return False
        reliable = ReliabilityPolicy.RELIABLE
        return (
            self.qos_profile.reliability == reliable
            and subscription.qos_profile.reliability == reliable
        ) or context.discovered(
            self.created_ns, subscription.created_ns, lag_ns=context.subscription_side_lag_ns
        )

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"Expected {self.msg_type.__name__}, got {type(msg).__name__}")
        context = self.node.context
        with context.condition:
            self._written += 1
            written = Written(msg, context.time_source.system_ns(), self._written)
            if self.qos_profile.durability.name == "TRANSIENT_LOCAL":
                self._history.append(Written(wire_copy(msg), written.source_ns, self._written))
            for subscription in context.subscriptions:
                if subscription.matches_topic(self) and self._reaches(subscription):
                    subscription.offer(self, written)
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
        callback_group: CallbackGroup,
    ) -> None:
        self.node, self.msg_type, self.topic_name = node, msg_type, topic
        self.callback, self.qos_profile = callback, qos
        self.callback_group = callback_group
        self.event_callbacks = event_callbacks or SubscriptionEventCallbacks()
        # (message, MessageInfo), oldest first
        self.pending: deque[tuple[Any, dict[str, Any]]] = deque(
            maxlen=qos.depth if qos.history.name == "KEEP_LAST" else None
        )
        self.incompatible = QoSRequestedIncompatibleQoSInfo()
        self.pending_events: list[QoSRequestedIncompatibleQoSInfo] = []
        self._incompatible_with: set[int] = set()
        self.created_ns = node.context.time_source.steady_ns()

    def take(self) -> tuple[Any, dict[str, Any]] | None:
        """The oldest message waiting and its MessageInfo, or None (what rclpy's
        take_message gives a subscription no executor runs)."""
        with self.node.context.condition:
            return self.pending.popleft() if self.pending else None

    # rclpy's subscription.handle: a context manager whose take_message(msg_type, raw)
    # gives (message, info) or None
    raw = False

    @property
    def handle(self) -> Subscription:
        return self

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def take_message(self, msg_type: type, raw: bool) -> tuple[Any, dict[str, Any]] | None:
        return self.take()

    def matches_topic(self, publisher: Publisher) -> bool:
        return publisher.topic_name == self.topic_name and type_name_of(
            publisher.msg_type
        ) == type_name_of(self.msg_type)

    def offer(self, publisher: Publisher, written: Written) -> None:
        """Deliver a copy of ``written`` if QoS allows (caller holds the context
        condition)."""
        policy = incompatible_policy(publisher.qos_profile, self.qos_profile)
        if policy is not None:
            self._note_incompatible(publisher, policy)
            return
        self._receive(publisher, written)

    def _receive(self, publisher: Publisher, written: Written) -> None:
        """Keep a copy of the message with its MessageInfo, as rclpy's take gives it:
        the keys and the kinds of value of real rclpy on Fast DDS (a reception
        sequence number it does not give: None)."""
        info = {
            "source_timestamp": written.source_ns,
            "received_timestamp": self.node.context.time_source.system_ns(),
            "publication_sequence_number": written.sequence,
            "reception_sequence_number": None,
            "publisher_gid": {"implementation_identifier": "rmw_mock", "data": publisher.gid},
        }
        self.pending.append((wire_copy(written.msg), info))

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
                for written in publisher._history:
                    self._receive(publisher, written)
