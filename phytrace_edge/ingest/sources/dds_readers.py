"""The ``dds`` input's readers (``DdsReaders``): one per topic, on the robot's domain,
matched to what the topic's writers offer by the ``ros`` input's QoS rules
(``ingest.qos``), and read as the input's doc (``dds.py``) says (every-message topics by a listener,
state topics at the sample tick, one sample at a time: ``take_each``; a state topic named
in ``SourceOptions.every_message``, an incident's trigger topic, by a listener too, its
QoS still matched as a state stream's; one named in ``SourceOptions.full_rate``, an
incident's window topic, at the tick, every sample since the last).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import LOG_EVERY_S, Take, TakenMessage, TakenUnreadable
from phytrace_edge.ingest.qos import QosChoice, before_publishers, incompatible, matching_qos
from phytrace_edge.ingest.sources.base import OnMessage, age_at_take
from phytrace_edge.ingest.sources.dds_wire import (
    FULL_RATE_DEPTH,
    READER_DEPTH,
    UNDECODABLE,
    dds_topic_name,
    domain_config,
    take_each,
)
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

if TYPE_CHECKING:  # imported with cyclonedds, when the input starts
    from phytrace_edge.ingest.sources.dds_graph import Publications

log = logging.getLogger(__name__)


def _ignore_unreadable(topic: str, reason: str, detail: str) -> None:
    """Readers whose owner does not count what could not be decoded."""


@dataclass
class ReadTopic:
    """One topic the input reads: its DDS topic, the reader it has now and the QoS that
    reader asks for, and what the graph says of the topic's writers."""

    name: str  # canonical, or the TOPICS_EXTRA entry's name
    topic: Any  # the cyclonedds Topic
    dds_name: str  # rt/...
    type_name: str  # the DDS type name, e.g. nav_msgs::msg::dds_::Odometry_
    every_message: bool  # the table's: every message counts (read reliably until matched)
    extra: bool
    choice: QosChoice
    # a state stream delivered on every message all the same (an incident's trigger
    # topic): read by a listener, its QoS matched as a state stream's
    called_back: bool = False
    # a state stream of which every sample counts (an incident's window topic): its
    # reader keeps FULL_RATE_DEPTH, all taken at the tick
    full_rate: bool = False
    reader: Any = None
    publishers: int = 0
    qos_incompatible: int = 0
    emptied_at: float = 0.0  # monotonic s when its reader was last emptied (or made)

    @property
    def listened(self) -> bool:
        """Delivered by a listener as each sample arrives, never taken at the tick."""
        return self.every_message or self.called_back


class DdsReaders:
    """A reader per enabled topic, matched to what the topic's writers offer by the
    ``ros`` input's rules (``ingest.qos``: reliable for the every-message topics until
    their writers are known, then what every writer can match; ``TOPIC_QOS``
    overrides). Every-message topics, and the state topics named in ``called_back``
    (an incident's trigger topics, ``SourceOptions.every_message``), go to
    ``on_message`` on Cyclone's listener thread, as they arrive; the others are taken
    at the sample tick and returned (``take_latest``), for the sampler to hand to the
    dispatcher: the newest sample of each, and every sample of those named in
    ``full_rate`` (an incident's window topics: a listener's call costs more CPU than
    the sample, docs/benchmarks.md)."""

    def __init__(
        self,
        topics: Mapping[str, str],
        on_message: OnMessage,
        domain_id: int,
        localhost_only: bool,
        extras: Mapping[str, tuple[str, str]] | None = None,
        cyclonedds_uri: str = "",
        on_unreadable: Callable[[str, str, str], None] = _ignore_unreadable,
        overrides: Mapping[str, QosChoice] | None = None,
        called_back: frozenset[str] = frozenset(),
        full_rate: frozenset[str] = frozenset(),
    ) -> None:
        try:
            from cyclonedds.core import DDSException
            from cyclonedds.domain import Domain, DomainParticipant
            from cyclonedds.internal import InvalidSample

            from phytrace_edge.ingest.sources.dds_graph import Publications
            from phytrace_edge.ingest.sources.dds_types import DDS_TYPES
        except ImportError:
            raise ConfigError(
                "BRIDGE_INPUT=dds: needs cyclonedds (pip install 'phytrace-edge[dds]')"
            ) from None
        # the Domain object carries the configuration: it must live as long as the readers
        self._domain = Domain(domain_id, domain_config(localhost_only, cyclonedds_uri))
        self.participant: Any = DomainParticipant(domain_id)
        self._on_message = on_message
        self._on_unreadable = on_unreadable
        self._overrides = dict(overrides or {})
        self._called_back = called_back - full_rate
        self._full_rate = full_rate
        self.queue_full: Counter[str] = Counter()
        self._dds_error = DDSException
        self._invalid_sample = InvalidSample
        self._lock = threading.Lock()  # the tick's takes and the graph check's re-matching
        self._failures_lock = threading.Lock()
        self._failures_logged: dict[str, float] = {}
        self._topics: dict[str, ReadTopic] = {}
        self.skipped: dict[str, str] = {}
        self.without_data: Counter[str] = Counter()
        self._graph: Publications | None = Publications(self.participant)
        for name, (actual, type_name) in (extras or {}).items():
            idl = self._extra_type(name, type_name)
            if idl is not None:
                self._add(name, actual, idl, every_message=False, extra=True)
        for canonical, actual in topics.items():
            spec = TOPIC_BY_NAME[canonical]
            # one type per DDS topic name: /cmd_vel is read as Twist, not TwistStamped
            self._add(canonical, actual, DDS_TYPES[spec.type_name], spec.every_message, False)
        log.info(
            "DDS: domain %d%s, %d readers",
            domain_id,
            " (localhost only)" if localhost_only else "",
            len(self._topics),
        )

    def _add(self, name: str, actual: str, idl: Any, every_message: bool, extra: bool) -> None:
        """Read topic ``actual`` as ``name``, as ``before_publishers`` says (or its
        override) until its writers are known."""
        from cyclonedds.topic import Topic

        dds_name = dds_topic_name(actual)
        topic = Topic(self.participant, dds_name, idl)
        choice = self._overrides.get(name) or before_publishers(every_message)
        read = ReadTopic(
            name,
            topic,
            dds_name,
            idl.__idl_typename__,
            every_message,
            extra,
            choice,
            called_back=name in self._called_back,
            full_rate=not every_message and name in self._full_rate,
        )
        self._topics[name] = read
        self._open(read, choice)

    def _open(self, read: ReadTopic, choice: QosChoice) -> None:
        """A reader for ``read`` asking for ``choice`` (which ``read`` then holds: a
        reader that could not be made is tried again at the next look): keep one
        sample of a state topic taken at the tick, 100 of a topic delivered by a
        listener (an every-message topic, a state topic called back), FULL_RATE_DEPTH of
        a full-rate one."""
        from cyclonedds.core import Listener, Policy, Qos
        from cyclonedds.sub import DataReader

        depth = FULL_RATE_DEPTH if read.full_rate else READER_DEPTH if read.listened else 1
        qos = Qos(
            Policy.Reliability.Reliable(max_blocking_time=0)
            if choice.reliable
            else Policy.Reliability.BestEffort,
            Policy.Durability.TransientLocal
            if choice.transient_local
            else Policy.Durability.Volatile,
            Policy.History.KeepLast(depth),
        )
        listener = None
        if read.listened:

            def deliver(reader: Any, name: str = read.name) -> None:
                self._take(name, reader, READER_DEPTH, self._deliver)

            listener = Listener(on_data_available=deliver)  # type: ignore[no-untyped-call]
        read.reader = DataReader(self.participant, read.topic, qos=qos, listener=listener)
        read.choice, read.emptied_at = choice, time.monotonic()

    def _extra_type(self, name: str, type_name: str) -> Any:
        """The DDS type of an extra topic, or None (and why, in ``skipped``)."""
        try:
            if not type_name:
                raise LookupError("the dds input needs its type (type=pkg/msg/Name)")
            from phytrace_edge.ingest.sources.dds_dynamic import idl_type

            return idl_type(type_name)
        except KeyError:
            reason = f"type {type_name} is not a ROS 2 Jazzy message the dds input knows"
        except ImportError as exc:  # the message definitions are rosbags' (the bag extra)
            reason = (
                f"the dds input makes its type from rosbags' message definitions, and "
                f"rosbags is not installed ({exc}): pip install 'phytrace-edge[bag]'"
            )
        except LookupError as exc:
            reason = str(exc)
        self.skipped[name] = reason
        log.warning("TOPICS_EXTRA %s: skipped - %s", name, reason)
        return None

    def refresh(self) -> None:
        """Look at the domain's writers: count each topic's, and read a topic anew when
        its writers need another QoS (a best-effort diagnostics writer, which a
        reliable reader cannot match; a latched goal, which only a transient-local
        reader receives from before). Never raises: a failed look waits for the next."""
        graph = self._graph
        try:
            offers = graph.offers() if graph is not None else {}
        except Exception as exc:  # the domain is going away, ...
            self._failed("(graph)", "reading the domain's writers", exc)
            return
        for read in list(self._topics.values()):
            offered = offers.get((read.dds_name, read.type_name), [])
            read.publishers = len(offered)
            if not offered:  # nobody now: keep listening as before
                read.qos_incompatible = 0
                continue
            choice = self._overrides.get(read.name) or matching_qos(offered)
            read.qos_incompatible = incompatible(choice, offered)
            if choice != read.choice or read.reader is None:
                try:
                    self._rematch(read, choice)
                except Exception as exc:  # no reader now: made again at the next look
                    self._failed(read.name, "making its reader", exc)

    def _rematch(self, read: ReadTopic, choice: QosChoice) -> None:
        """Replace ``read``'s reader by one asking for ``choice``; what the old one
        held is handed over first."""
        with self._lock:
            old, read.reader = read.reader, None
            if old is not None and read.listened:
                old.set_listener(None)  # no call of its listener runs after this returns
                self._take(read.name, old, READER_DEPTH, self._deliver)
            elif old is not None:  # not at a tick: handed over at once
                self._take_waiting(read, old, self._deliver)
            del old  # the last reference: Cyclone deletes the reader now, on this thread
            self._open(read, choice)
        log.info(
            "%s: reading %s (%s) as %s",
            read.name,
            read.dds_name,
            read.type_name,
            choice.describe(),
        )

    def take_latest(self, due: Callable[[str], bool] = lambda name: True) -> list[Take]:
        """The newest sample of each state topic, if one came since last time, with its
        age (or, when it could not be decoded, why); every sample of a full-rate one;
        an extra topic's only when it is ``due`` (its rate_hz), so a large one sent
        once a second is not deserialised at every tick. Returned, not handed over:
        the sampler dispatches them."""
        takes: list[Take] = []
        with self._lock:
            for read in self._topics.values():
                if read.listened or read.reader is None:
                    continue  # delivered as they come, never also at the tick
                if read.extra and not read.full_rate and not due(read.name):
                    continue  # left in Cyclone's cache (one sample), not deserialised
                self._take_waiting(read, read.reader, takes.append)
        return takes

    def _take_waiting(self, read: ReadTopic, reader: Any, put: Callable[[Take], None]) -> None:
        """What a state topic's ``reader`` keeps (one sample; all of a full-rate
        topic's, oldest first), each with its age, to ``put``. A full-rate reader found
        full may have lost its oldest: counted in ``queue_full``."""
        now = time.monotonic()
        waited_s, read.emptied_at = now - read.emptied_at, now
        if not read.full_rate:
            self._take(read.name, reader, 1, put, waited_s)
            return
        taken: list[Take] = []
        self._take(read.name, reader, FULL_RATE_DEPTH, taken.append, waited_s)
        if len(taken) >= FULL_RATE_DEPTH:
            self.queue_full[read.name] += 1
            if self.queue_full[read.name] == 1:
                log.warning(
                    "%s: %d samples waited for one tick, as many as are kept: older ones "
                    "may have been lost (a faster topic than the incident window can keep "
                    "at this SAMPLE_RATE_HZ)",
                    read.name,
                    FULL_RATE_DEPTH,
                )
        for take in taken:
            put(take)

    def _take(
        self,
        name: str,
        reader: Any,
        limit: int,
        put: Callable[[Take], None],
        waited_s: float | None = None,
    ) -> None:
        """Up to ``limit`` samples of topic ``name``, one at a time (``take_each``),
        each to ``put`` as it is taken (``_deliver``: handed over now; or kept, for the
        sampler to dispatch); never raises: it runs on Cyclone's listener thread, where
        an exception is only printed, and at the sample tick, which must go on for the
        other topics. ``waited_s``: how long the samples can have waited in the reader
        (None: they are delivered as they arrive)."""
        try:
            take_each(
                reader,
                limit,
                lambda sample: self._hand_over(name, sample, waited_s, put),
                lambda exc: put(TakenUnreadable(name, UNDECODABLE, f"{type(exc).__name__}: {exc}")),
                self._dds_error,
            )
        except Exception as exc:  # the C take failed (the reader is being deleted, ...)
            self._failed(name, "taking samples from DDS", exc)

    def _hand_over(
        self, name: str, sample: Any, waited_s: float | None, put: Callable[[Take], None]
    ) -> None:
        """A sample with data to ``put``, with its age when it waited in the reader
        (Cyclone gives no reception time: the writer's stamp, bounded by the wait,
        ``age_at_take``); one without (a writer that went away disposed or
        unregistered its instance) is only counted: it is no message, and a topic goes
        stale by its age, not by its publisher leaving."""
        if isinstance(sample, self._invalid_sample):
            self.without_data[name] += 1
            return
        age_s = 0.0
        if waited_s is not None:
            written_ns = int(getattr(sample.sample_info, "source_timestamp", 0) or 0)
            age_s = age_at_take(written_ns, time.time_ns(), waited_s)
        put(TakenMessage(name, sample, age_s))

    def _deliver(self, take: Take) -> None:
        """A sample taken outside the tick (by a listener, from a replaced reader),
        handed over at once: to ``on_message``, or ``on_unreadable``."""
        if isinstance(take, TakenMessage):
            self._on_message(take.topic, take.message, take.age_s)
        else:
            self._on_unreadable(take.topic, take.reason, take.detail)

    def _failed(self, name: str, what: str, exc: Exception) -> None:
        """Log a failure at WARNING, at most once a minute per topic and kind."""
        now = time.monotonic()
        with self._failures_lock:
            last = self._failures_logged.get(f"{name} {what}")
            if last is not None and now - last < LOG_EVERY_S:
                return
            self._failures_logged[f"{name} {what}"] = now
        log.warning("%s: %s failed: %s: %s", name, what, type(exc).__name__, exc)

    def stats(self) -> dict[str, dict[str, Any]]:
        """Per topic: its writers on the domain, the QoS it is read with, and how many
        writers that QoS cannot match (as the ``ros`` input shows them)."""
        return {
            name: {
                "publishers": read.publishers,
                "qos": read.choice.describe(),
                "qos_incompatible": read.qos_incompatible,
                **({"queue_full": self.queue_full[name]} if self.queue_full.get(name) else {}),
            }
            for name, read in list(self._topics.items())
        }

    def close(self) -> None:
        """Let go of the readers, the graph's reader and the participant (Cyclone
        deletes each as its last reference goes)."""
        with self._lock:
            for read in self._topics.values():
                read.reader = None
            self._topics.clear()
        self._graph = None
        self.participant = None
