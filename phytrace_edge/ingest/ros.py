"""The rclpy side of ingest: subscriptions that feed the dispatcher, and the sample timer.

Everything rclpy-specific goes through ``RosApi``, so this code runs unchanged on real
rclpy (``load_rclpy()``, imported lazily: rclpy is not on PyPI and the core must work
without it) and on the mock layer the simulator and the tests use.
"""

from __future__ import annotations

import importlib
import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

log = logging.getLogger(__name__)

SAMPLED_QUEUE_DEPTH = 5
EVERY_MESSAGE_QUEUE_DEPTH = 100


@dataclass(frozen=True)
class RosApi:
    """The parts of rclpy the bridge uses."""

    create_node: Callable[..., Any]
    message_type: Callable[[str], type]
    qos: Any  # the rclpy.qos module: QoSProfile and the policy enums
    clock: Callable[[str], Any]  # "steady" or "system" -> an rclpy Clock
    subscription_events: Callable[[Callable[[Any], None]], Any]  # incompatible-QoS callback


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

    try:  # Iron and later
        events = importlib.import_module("rclpy.event_handler")
    except ImportError:  # Humble
        events = importlib.import_module("rclpy.qos_event")

    def subscription_events(on_incompatible: Callable[[Any], None]) -> Any:
        return events.SubscriptionEventCallbacks(incompatible_qos=on_incompatible)

    return RosApi(rclpy.create_node, message_type, qos, make_clock, subscription_events)


class NodeClock:
    """The builder's clock read from ROS clocks (so simulated time is honoured)."""

    def __init__(self, api: RosApi) -> None:
        self._steady = api.clock("steady")
        self._system = api.clock("system")

    def monotonic(self) -> float:
        return float(self._steady.now().nanoseconds) / 1e9

    def wall(self) -> float:
        return float(self._system.now().nanoseconds) / 1e9


@dataclass(frozen=True)
class QosChoice:
    """What a subscription asks for: the part of QoS that decides matching."""

    reliable: bool
    transient_local: bool

    def describe(self) -> str:
        return (
            f"{'reliable' if self.reliable else 'best effort'}, "
            f"{'transient local' if self.transient_local else 'volatile'}"
        )


def matching_qos(offered: list[tuple[bool, bool]]) -> QosChoice:
    """The QoS that receives from every publisher (the rule rosbag2 and foxglove_bridge
    use): reliable only when every publisher is reliable, transient local only when
    every publisher is. ``offered`` holds (reliable, transient_local) per publisher."""
    return QosChoice(
        reliable=bool(offered) and all(reliable for reliable, _ in offered),
        transient_local=bool(offered) and all(latched for _, latched in offered),
    )


class TopicSubscriber:
    """One subscription per enabled topic, matched to what its publishers offer.

    ``refresh`` (at start and then periodically) subscribes topics whose publishers
    appeared since, and re-creates a subscription when a new publisher would be
    incompatible with it; topics with no publisher are skipped. A per-topic override
    (TOPIC_QOS) replaces the matching. Incompatible-QoS events are counted per topic.
    """

    def __init__(
        self,
        api: RosApi,
        node: Any,
        topics: dict[str, str],
        dispatcher: Dispatcher,
        overrides: dict[str, QosChoice] | None = None,
    ) -> None:
        self._api, self._node, self._topics = api, node, topics
        self._dispatcher = dispatcher
        self._overrides = overrides or {}
        self.subscribed: dict[str, tuple[Any, QosChoice, str]] = {}
        self.qos_incompatible: Counter[str] = Counter()

    def refresh(self) -> None:
        for canonical, actual in self._topics.items():
            spec = TOPIC_BY_NAME[canonical]
            publishers = [
                info
                for info in self._node.get_publishers_info_by_topic(actual)
                if info.topic_type in spec.type_names
            ]
            if not publishers:
                continue
            choice = self._overrides.get(canonical) or matching_qos(
                [
                    (
                        info.qos_profile.reliability == self._api.qos.ReliabilityPolicy.RELIABLE,
                        info.qos_profile.durability
                        == self._api.qos.DurabilityPolicy.TRANSIENT_LOCAL,
                    )
                    for info in publishers
                ]
            )
            type_name = publishers[0].topic_type
            current = self.subscribed.get(canonical)
            if current is not None and current[1:] == (choice, type_name):
                continue
            if current is not None:
                self._node.destroy_subscription(current[0])
            self.subscribed[canonical] = (
                self._subscribe(canonical, actual, type_name, choice),
                choice,
                type_name,
            )
            log.info(
                "%s: subscribed to %s (%s) as %s", canonical, actual, type_name, choice.describe()
            )

    def _subscribe(self, canonical: str, actual: str, type_name: str, choice: QosChoice) -> Any:
        qos = self._api.qos
        depth = (
            EVERY_MESSAGE_QUEUE_DEPTH
            if TOPIC_BY_NAME[canonical].every_message
            else SAMPLED_QUEUE_DEPTH
        )
        profile = qos.QoSProfile(
            depth=depth,
            reliability=qos.ReliabilityPolicy.RELIABLE
            if choice.reliable
            else qos.ReliabilityPolicy.BEST_EFFORT,
            durability=qos.DurabilityPolicy.TRANSIENT_LOCAL
            if choice.transient_local
            else qos.DurabilityPolicy.VOLATILE,
        )

        def on_message(msg: Any) -> None:
            self._dispatcher.on_message(canonical, msg)

        def on_incompatible(event: Any) -> None:
            self.qos_incompatible[canonical] += 1
            log.warning(
                "%s: a publisher's QoS is incompatible with the subscription (%s)",
                canonical,
                choice.describe(),
            )

        return self._node.create_subscription(
            self._api.message_type(type_name),
            actual,
            on_message,
            profile,
            event_callbacks=self._api.subscription_events(on_incompatible),
        )


def create_sample_timer(api: RosApi, node: Any, rate_hz: float, on_tick: Callable[[], None]) -> Any:
    """The builder's tick, on the steady clock: wall-clock jumps and sim time never
    stretch or squeeze the sample rate."""
    return node.create_timer(1.0 / rate_hz, on_tick, clock=api.clock("steady"))
