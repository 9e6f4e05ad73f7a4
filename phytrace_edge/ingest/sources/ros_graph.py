"""Subscriptions on a ROS 2 graph, matched to what the publishers offer.

Everything rclpy-specific goes through ``RosApi``, so this code runs unchanged on real
rclpy (``sources/ros.py``, the one module that imports it) and on the mock layer the
simulator and the tests use (``sources/sim.py``).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

from phytrace_edge.ingest.dispatch import TakenMessage
from phytrace_edge.ingest.qos import QosChoice, before_publishers, incompatible, matching_qos
from phytrace_edge.ingest.sources.base import OnMessage, age_at_take
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

log = logging.getLogger(__name__)

SAMPLED_QUEUE_DEPTH = 5
EVERY_MESSAGE_QUEUE_DEPTH = 100
# a full-rate topic's messages wait in its subscription for the next tick: 2 s of a
# 500 Hz topic at 5 Hz ticks is 200; the rest is room for a late tick
FULL_RATE_QUEUE_DEPTH = 1000
GRAPH_CHECK_S = 2.0  # how often new topics and new publishers are looked for


class Taken(NamedTuple):
    """A message taken from a subscription, and when the middleware received it (ns
    on the system clock; 0 when it does not say)."""

    message: Any
    received_ns: int


@dataclass(frozen=True)
class RosApi:
    """The parts of rclpy the bridge uses."""

    create_node: Callable[..., Any]
    message_type: Callable[[str], type]
    qos: Any  # the rclpy.qos module: QoSProfile and the policy enums
    clock: Callable[[str], Any]  # "steady" or "system" -> an rclpy Clock
    subscription_events: Callable[[Callable[[Any], None]], Any]  # incompatible-QoS callback
    take: Callable[[Any], Taken | None]  # a subscription's newest message, or None
    # a read-only ParameterDescriptor with this description
    parameter_descriptor: Callable[[str], Any]
    callback_group_base: type  # rclpy.callback_groups.CallbackGroup


def taken_at_the_tick(api: RosApi) -> Any:
    """A callback group no executor runs: a subscription in it is never waited on and
    has no callback; the sampler takes its newest message at the tick. The node stays
    one node, spun for its timers and its parameter services (a second node that
    nobody spins would leave ``ros2 param list`` waiting forever)."""

    class TakenAtTheTick(api.callback_group_base):  # type: ignore[name-defined,misc]
        def can_execute(self, entity: Any) -> bool:
            return False

        def beginning_execution(self, entity: Any) -> bool:
            return False

        def ending_execution(self, entity: Any) -> None:
            return None

    return TakenAtTheTick()


def declare_settings(api: RosApi, node: Any, parameters: dict[str, tuple[Any, str]]) -> None:
    """The bridge's effective settings as read-only parameters of its node, so
    ``ros2 param list/get /phytrace_edge`` shows what it runs with (a change needs a
    restart: settings are read once, at start). The effective value, not rcl's
    override: an environment variable outranks ``-p``, and the parameter says so."""
    for name, (value, doc) in parameters.items():
        if not node.has_parameter(name):  # use_sim_time: the node declares it itself
            node.declare_parameter(name, value, api.parameter_descriptor(doc), ignore_override=True)


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
class Wanted:
    """A topic to subscribe: its name on the robot, the types accepted (empty: any, as
    the graph says) and the subscription's queue depth."""

    actual: str
    types: tuple[str, ...]
    depth: int
    sampled: bool = False  # a state stream: only its latest message counts
    extra: bool = False  # a TOPICS_EXTRA topic: taken at the tick only when it is due
    # a state stream called back on every message all the same: an incident's trigger
    # topic (its QoS is still matched as a state stream's)
    called_back: bool = False
    # a state stream of which every message counts, all of them taken at the tick (an
    # incident's window topic): no callback per message, a deeper subscription instead
    full_rate: bool = False


def wanted_topics(
    topics: dict[str, str],
    extras: dict[str, tuple[str, str]] | None = None,
    every_message: frozenset[str] = frozenset(),
    full_rate: frozenset[str] = frozenset(),
) -> dict[str, Wanted]:
    """The table's topics (canonical -> actual) and TOPICS_EXTRA's (name -> (actual,
    type or "")); those in ``every_message`` are called back on every message, those
    in ``full_rate`` taken whole at the tick (a state stream's; otherwise as
    ``every_message``)."""

    def depth(called_back: bool, all_taken: bool) -> int:
        if all_taken:
            return FULL_RATE_QUEUE_DEPTH
        return EVERY_MESSAGE_QUEUE_DEPTH if called_back else SAMPLED_QUEUE_DEPTH

    wanted = {}
    for canonical, actual in topics.items():
        sampled = not TOPIC_BY_NAME[canonical].every_message
        all_taken = sampled and canonical in full_rate
        called_back = sampled and canonical in every_message and not all_taken
        wanted[canonical] = Wanted(
            actual,
            TOPIC_BY_NAME[canonical].type_names,
            depth(not sampled or called_back, all_taken),
            sampled=sampled,
            called_back=called_back,
            full_rate=all_taken,
        )
    for name, (actual, type_name) in (extras or {}).items():
        types = (type_name,) if type_name else ()
        all_taken = name in full_rate
        called_back = name in every_message and not all_taken
        wanted[name] = Wanted(
            actual,
            types,
            depth(called_back, all_taken),
            sampled=True,
            extra=True,
            called_back=called_back,
            full_rate=all_taken,
        )
    return wanted


@dataclass(frozen=True)
class Subscription:
    """A topic's rclpy subscription, with the QoS and type it was made for."""

    handle: Any  # rclpy's Subscription
    qos: QosChoice
    type_name: str


class TopicSubscriber:
    """One subscription per enabled topic, matched to what its publishers offer.

    State streams are taken at the sample tick when ``take_at_tick`` is set: their
    subscriptions sit in a callback group no executor runs (``taken_at_the_tick``), so
    no Python runs for each of their messages. A full-rate one (an incident's window
    topic) keeps up to FULL_RATE_QUEUE_DEPTH messages, and the tick takes them all, in
    order, each with its own reception stamp: rclpy's executor costs ~600 us of CPU a
    message to call a callback (a bare node's), where taking it at the tick and
    handling it costs ~100 in all (docs/benchmarks.md, "Incident window").
    A take that empties a full queue may have lost its oldest: counted in
    ``queue_full`` by topic.

    ``refresh`` (at start and then periodically) subscribes every topic at once (while
    no publisher is known: ``qos.before_publishers``), and re-creates
    a subscription when its publishers need another QoS (reliable, transient local: a
    latched goal) or another type; an extra topic with no type given waits for one. A
    per-topic override (TOPIC_QOS) replaces the matching. Incompatible-QoS events are
    counted per topic, and so is a type this machine has no message class for (an
    extra topic's).

    A message taken at the tick carries its age: the middleware's reception stamp
    (``age_at_take``). An extra topic is taken only when ``due`` says so (its own
    ``rate_hz``), so a large message sent once a second is not deserialised at
    every tick.
    """

    def __init__(
        self,
        api: RosApi,
        node: Any,
        topics: dict[str, Wanted],
        on_message: OnMessage,
        overrides: dict[str, QosChoice] | None = None,
        take_at_tick: bool = False,
        due: Callable[[str], bool] = lambda topic: True,
    ) -> None:
        self._api, self._node, self._topics = api, node, topics
        self._taken_at_tick = taken_at_the_tick(api) if take_at_tick else None
        self._lock = threading.Lock()
        self._on_message = on_message
        self._overrides = overrides or {}
        self._due = due
        self._system, self._steady = api.clock("system"), api.clock("steady")
        # steady seconds when each taken subscription was last emptied (or made)
        self._emptied_at: dict[str, float] = {}
        self.subscribed: dict[str, Subscription] = {}
        self.publishers: dict[str, int] = dict.fromkeys(topics, 0)
        self.qos_incompatible: Counter[str] = Counter()
        self.queue_full: Counter[str] = Counter()
        self.type_unknown: dict[str, str] = {}

    def refresh(self) -> None:
        with self._lock:  # the sampler's take_latest uses the same subscriptions
            kept = self._refresh()
        for taken in kept:  # not at a tick: handed over as a callback hands its message
            self._on_message(taken.topic, taken.message, taken.age_s)

    def _refresh(self) -> list[TakenMessage]:
        """Subscribe and re-match; the messages (and their ages) taken from the
        subscriptions it replaced."""
        kept: list[TakenMessage] = []
        for canonical, wanted in self._topics.items():
            publishers = [
                info
                for info in self._node.get_publishers_info_by_topic(wanted.actual)
                if not wanted.types or info.topic_type in wanted.types
            ]
            self.publishers[canonical] = len(publishers)
            current = self.subscribed.get(canonical)
            if canonical in self.type_unknown:
                continue
            offered = [
                (
                    info.qos_profile.reliability == self._api.qos.ReliabilityPolicy.RELIABLE,
                    info.qos_profile.durability == self._api.qos.DurabilityPolicy.TRANSIENT_LOCAL,
                )
                for info in publishers
            ]
            if publishers:
                choice = self._overrides.get(canonical) or matching_qos(offered)
                type_name = publishers[0].topic_type
                if self._is_taken(wanted):  # no executor runs its events
                    self._count_incompatible(canonical, choice, offered)
            elif current is None and wanted.types:
                # nobody seen yet: listen from now on anyway (``before_publishers``), so
                # nothing published before the next look at the graph is lost (a
                # one-shot diagnostics ERROR)
                choice = self._overrides.get(canonical) or before_publishers(not wanted.sampled)
                type_name = wanted.types[0]
            else:
                continue
            if current is not None and (current.qos, current.type_name) == (choice, type_name):
                continue
            try:
                message_class = self._api.message_type(type_name)
            except (ImportError, AttributeError, KeyError, ValueError):
                self.type_unknown[canonical] = type_name
                log.warning(
                    "%s: type %s is not installed here - the topic is skipped", canonical, type_name
                )
                continue
            if current is not None:
                if self._is_taken(wanted):  # what waits in it was not taken yet
                    kept += self._take(canonical, wanted, current.handle)
                self._node.destroy_subscription(current.handle)
            self._emptied_at[canonical] = self._steady_s()
            self.subscribed[canonical] = Subscription(
                self._subscribe(canonical, wanted, message_class, choice), choice, type_name
            )
            log.info(
                "%s: subscribed to %s (%s) as %s",
                canonical,
                wanted.actual,
                type_name,
                choice.describe(),
            )
        return kept

    def stats(self) -> dict[str, dict[str, Any]]:
        """Per configured topic: publishers seen, the QoS subscribed with, and how many
        publishers' QoS could not be matched."""
        return {
            canonical: {
                "publishers": self.publishers.get(canonical, 0),
                "qos": self.subscribed[canonical].qos.describe()
                if canonical in self.subscribed
                else None,
                "qos_incompatible": self.qos_incompatible.get(canonical, 0),
                **(
                    {"queue_full": self.queue_full[canonical]}
                    if self.queue_full.get(canonical)
                    else {}
                ),
                **(
                    {"type_unknown": self.type_unknown[canonical]}
                    if canonical in self.type_unknown
                    else {}
                ),
            }
            for canonical in self._topics
        }

    def _count_incompatible(
        self, canonical: str, choice: QosChoice, offered: list[tuple[bool, bool]]
    ) -> None:
        """Publishers the subscription cannot match, read off the graph (a reliable or
        transient-local request meets a best-effort or volatile offer)."""
        count = incompatible(choice, offered)
        if count > self.qos_incompatible[canonical]:
            log.warning(
                "%s: %d publisher(s)' QoS incompatible with the subscription (%s)",
                canonical,
                count,
                choice.describe(),
            )
            self.qos_incompatible[canonical] = count

    def take_latest(self) -> list[TakenMessage]:
        """The newest message of each sampled topic, if one came since the last tick
        (no executor runs their subscriptions), with its age; every message of a
        full-rate topic; an extra topic's only when it is due. Returned, not handed
        over: the sampler dispatches them."""
        taken = []
        with self._lock:
            for canonical, wanted in self._topics.items():
                current = self.subscribed.get(canonical)
                if current is None or not self._is_taken(wanted):
                    continue
                if wanted.extra and not wanted.full_rate and not self._due(canonical):
                    continue  # left in the subscription (keep last 1), not deserialised
                taken += self._take(canonical, wanted, current.handle)
        return taken

    def _take(self, canonical: str, wanted: Wanted, subscription: Any) -> list[TakenMessage]:
        """What waits on a taken subscription, oldest first, each with its age: the
        newest message (the subscription keeps one), or all of a full-rate topic's."""
        now_s = self._steady_s()
        waited_s = now_s - self._emptied_at.get(canonical, now_s)
        self._emptied_at[canonical] = now_s
        waiting = []
        for _ in range(FULL_RATE_QUEUE_DEPTH if wanted.full_rate else 1):
            taken = self._api.take(subscription)
            if taken is None:
                break
            waiting.append(taken)
        if wanted.full_rate and len(waiting) >= FULL_RATE_QUEUE_DEPTH:
            self._count_full(canonical)
        now_ns = int(self._system.now().nanoseconds)
        return [
            TakenMessage(canonical, t.message, age_at_take(t.received_ns, now_ns, waited_s))
            for t in waiting
        ]

    def _count_full(self, canonical: str) -> None:
        """A full-rate subscription found full: messages beyond its depth may have been
        replaced before this take (its topic publishes faster than it can be kept
        between two ticks)."""
        self.queue_full[canonical] += 1
        if self.queue_full[canonical] == 1:
            log.warning(
                "%s: %d messages waited for one tick, as many as are kept: older ones may "
                "have been lost (a faster topic than the incident window can keep at "
                "this SAMPLE_RATE_HZ)",
                canonical,
                FULL_RATE_QUEUE_DEPTH,
            )

    def _steady_s(self) -> float:
        return float(self._steady.now().nanoseconds) / 1e9

    def _is_taken(self, wanted: Wanted) -> bool:
        """Whether this topic is taken at the tick rather than called back."""
        return wanted.sampled and not wanted.called_back and self._taken_at_tick is not None

    def _subscribe(
        self, canonical: str, wanted: Wanted, message_class: type, choice: QosChoice
    ) -> Any:
        qos = self._api.qos
        sampled = self._is_taken(wanted)
        profile = qos.QoSProfile(
            depth=1 if sampled and not wanted.full_rate else wanted.depth,
            reliability=qos.ReliabilityPolicy.RELIABLE
            if choice.reliable
            else qos.ReliabilityPolicy.BEST_EFFORT,
            durability=qos.DurabilityPolicy.TRANSIENT_LOCAL
            if choice.transient_local
            else qos.DurabilityPolicy.VOLATILE,
        )

        def on_message(msg: Any) -> None:
            self._on_message(canonical, msg)

        def on_incompatible(event: Any) -> None:
            self.qos_incompatible[canonical] += 1
            log.warning(
                "%s: a publisher's QoS is incompatible with the subscription (%s)",
                canonical,
                choice.describe(),
            )

        return self._node.create_subscription(
            message_class,
            wanted.actual,
            (lambda msg: None) if sampled else on_message,  # taken at the tick instead
            profile,
            callback_group=self._taken_at_tick if sampled else None,
            event_callbacks=self._api.subscription_events(on_incompatible),
        )


def subscribe_topics(
    api: RosApi,
    node: Any,
    topics: dict[str, Wanted],
    on_message: OnMessage,
    overrides: dict[str, QosChoice] | None = None,
    take_at_tick: bool = False,
    due: Callable[[str], bool] = lambda topic: True,
) -> TopicSubscriber:
    """Subscribe ``node`` to the topics (state streams taken at the tick, if asked;
    an extra topic when ``due``), and look again every GRAPH_CHECK_S for publishers
    that need another QoS."""
    subscriber = TopicSubscriber(api, node, topics, on_message, overrides, take_at_tick, due)
    subscriber.refresh()
    node.create_timer(GRAPH_CHECK_S, subscriber.refresh, clock=api.clock("steady"))
    return subscriber
