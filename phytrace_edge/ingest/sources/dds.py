"""The ROS-free input (``BRIDGE_INPUT=dds``): hear a ROS 2 robot over Cyclone DDS
without ROS installed (the ``dds`` extra, PyPI ``cyclonedds``).

It reads ROS 2's own environment so it lands on the same DDS domain as the robot:
``ROS_DOMAIN_ID`` picks the domain, and ``ROS_LOCALHOST_ONLY=1`` or
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` confine it to loopback, as rmw_cyclonedds
does (a participant with Cyclone's defaults would see nothing of a localhost-only
robot). It hears Fast DDS publishers (ROS 2's default middleware) as well as
Cyclone ones: see ``domain_config``. Readers are best effort and volatile: they match
reliable and best-effort writers alike (a reliable reader would get nothing from a
best-effort sensor); a latched message published before the bridge started is not
received.

State topics (odometry, IMU, scan, ...) publish far faster than events are built and
only their latest value counts: their readers keep one sample, in Cyclone's C cache,
and ``take_latest`` deserialises it at the sample tick, so Python touches at most one
message per topic per tick instead of every message (an IMU at 200 Hz). Topics where
every message counts (diagnostics, goals, delivery status) are delivered as they come.
The topics of ``TOPICS_EXTRA`` are read like state topics, with types made from ROS 2
Jazzy's message definitions (``dds_dynamic.py``); one whose type is not given or not
known is skipped, with the reason in the log and in ``status``.

A sample that cannot be decoded (a string that is not UTF-8: cyclonedds decodes
strictly) costs only itself: samples are taken one at a time, and that one is counted
as its topic's reject ``undecodable``, as the bag input counts such a record.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import LOG_EVERY_S
from phytrace_edge.ingest.generic import FieldTypes, rosbags_field_types
from phytrace_edge.ingest.sources.base import Feed, Finished, SourceOptions
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

log = logging.getLogger(__name__)

READER_DEPTH = 100
UNDECODABLE = "undecodable"  # the reject reason of a sample that cannot be decoded (as bag's)
# Fast DDS announces XTypes type information that Cyclone DDS rejects ("invalid type
# object"), and a reader whose writer's type cannot be resolved never matches: not one
# sample. With eProsima's information ignored (1.15 is its DDS vendor id), type names
# decide, as they do for rmw_cyclonedds, whose types carry no type information.
FAST_DDS_TYPES_BY_NAME = (
    "<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation></Compatibility>"
)
LOCALHOST_ONLY = (
    "<General><Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>64</MaxAutoParticipantIndex>"
    "<Peers><Peer address='localhost'/></Peers></Discovery>"
)


def domain_config(localhost_only: bool, cyclonedds_uri: str = "") -> str:
    """The Cyclone configuration of the input's domain: the user's ``CYCLONEDDS_URI``
    (kept: Cyclone merges a comma-separated list), then Fast DDS interoperability and,
    if asked, loopback only."""
    ours = (
        "<CycloneDDS><Domain id='any'>"
        + FAST_DDS_TYPES_BY_NAME
        + (LOCALHOST_ONLY if localhost_only else "")
        + "</Domain></CycloneDDS>"
    )
    return f"{cyclonedds_uri},{ours}" if cyclonedds_uri.strip() else ours


def dds_topic_name(ros_topic: str) -> str:
    """ROS 2's DDS name of a topic: ``/odom`` -> ``rt/odom``."""
    return "rt" + ros_topic


def _ignore_unreadable(topic: str, reason: str, detail: str) -> None:
    """Readers whose owner does not count what could not be decoded."""


# What cyclonedds-python 11.0.1 does with a sample it cannot decode (measured on real
# Cyclone DDS: a std_msgs String whose CDR string holds 0xff 0xfe): ``take(N=k)``
# first takes up to k serialised samples out of the reader's cache in C, then decodes
# them in Python; a string that is not UTF-8 makes the decoding raise
# ``UnicodeDecodeError`` out of ``take``, and the k samples it took are gone, the good
# ones with the bad (a second ``take`` returns nothing). ``take(N=1)`` on the bad one
# raises the same and removes it: the next ``take(N=1)`` returns the sample after it.
# Only an error of the C take (``DDSException``) leaves the cache as it was.
# Cyclone calls a listener as each sample arrives (2,000 samples of a burst from
# another process: 2,000 calls, each finding one sample, even with a busy Python
# thread), so a batch is rare there; but an exception out of a listener is only
# printed by ctypes ("Exception ignored on calling ctypes callback function", with its
# traceback), the sample never counted; and out of the tick's take it ended the
# sampler thread, for each bad sample (its supervisor restarted it, logging an
# ERROR), and the topics after it were not taken. Hence one at a time, never
# raising: a failing take costs its one sample, counted ``undecodable``; the extra
# take that finds the cache empty costs a call into C.
def take_each(
    reader: Any,
    limit: int,
    on_sample: Callable[[Any], None],
    on_undecodable: Callable[[Exception], None],
    dds_error: type[Exception],
) -> None:
    """Take up to ``limit`` samples from ``reader`` one at a time, until it has no
    more: each to ``on_sample``, or, when it cannot be decoded, its exception to
    ``on_undecodable``. A ``dds_error`` (the C take failed: nothing was taken)
    propagates."""
    for _ in range(limit):
        try:
            samples = reader.take(N=1)
        except dds_error:
            raise
        except Exception as exc:  # raised while decoding: that sample is taken, and lost
            on_undecodable(exc)
            continue
        if not samples:
            return
        for sample in samples:
            on_sample(sample)


class DdsReaders:
    """One best-effort reader per enabled topic; samples go to ``on_message`` on
    Cyclone's listener thread."""

    def __init__(
        self,
        topics: Mapping[str, str],
        on_message: Callable[[str, Any], None],
        domain_id: int,
        localhost_only: bool,
        extras: Mapping[str, tuple[str, str]] | None = None,
        cyclonedds_uri: str = "",
        on_unreadable: Callable[[str, str, str], None] = _ignore_unreadable,
    ) -> None:
        try:
            from cyclonedds.core import DDSException, Listener, Policy, Qos
            from cyclonedds.domain import Domain, DomainParticipant
            from cyclonedds.internal import InvalidSample
            from cyclonedds.sub import DataReader
            from cyclonedds.topic import Topic

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
        self._dds_error = DDSException
        self._failures_lock = threading.Lock()
        self._failures_logged: dict[str, float] = {}
        self.readers: list[Any] = []
        self.latest_readers: list[tuple[str, Any]] = []
        self.skipped: dict[str, str] = {}
        self.without_data: Counter[str] = Counter()
        self._invalid_sample = InvalidSample

        def qos(depth: int) -> Any:
            return Qos(
                Policy.Reliability.BestEffort,
                Policy.Durability.Volatile,
                Policy.History.KeepLast(depth),
            )

        for name, (actual, type_name) in (extras or {}).items():
            idl = self._extra_type(name, type_name)
            if idl is not None:
                topic = Topic(self.participant, dds_topic_name(actual), idl)
                reader = DataReader(self.participant, topic, qos=qos(1))
                self.latest_readers.append((name, reader))
                self.readers.append(reader)
        for canonical, actual in topics.items():
            spec = TOPIC_BY_NAME[canonical]
            # one type per DDS topic name: /cmd_vel is read as Twist, not TwistStamped
            topic = Topic(self.participant, dds_topic_name(actual), DDS_TYPES[spec.type_name])
            depth = READER_DEPTH if spec.every_message else 1
            if spec.every_message:

                def deliver(reader: Any, name: str = canonical) -> None:
                    self._take(name, reader, READER_DEPTH)

                reader = DataReader(
                    self.participant,
                    topic,
                    qos=qos(depth),
                    listener=Listener(on_data_available=deliver),
                )
            else:
                reader = DataReader(self.participant, topic, qos=qos(depth))
                self.latest_readers.append((canonical, reader))
            self.readers.append(reader)
        log.info(
            "DDS: domain %d%s, %d readers",
            domain_id,
            " (localhost only)" if localhost_only else "",
            len(self.readers),
        )

    def _extra_type(self, name: str, type_name: str) -> Any:
        """The DDS type of an extra topic, or None (and why, in ``skipped``)."""
        from phytrace_edge.ingest.sources.dds_dynamic import idl_type

        try:
            if not type_name:
                raise LookupError("the dds input needs its type (type=pkg/msg/Name)")
            return idl_type(type_name)
        except KeyError:
            reason = f"type {type_name} is not a ROS 2 Jazzy message the dds input knows"
        except LookupError as exc:
            reason = str(exc)
        self.skipped[name] = reason
        log.warning("TOPICS_EXTRA %s: skipped - %s", name, reason)
        return None

    def take_latest(self) -> None:
        """Hand over the newest sample of each state topic, if one came since last time."""
        for name, reader in self.latest_readers:
            self._take(name, reader, 1)

    def _take(self, name: str, reader: Any, limit: int) -> None:
        """Up to ``limit`` samples of topic ``name``, one at a time (``take_each``);
        never raises: it runs on Cyclone's listener thread, where an exception is only
        printed, and at the sample tick, which must go on for the other topics."""
        try:
            take_each(
                reader,
                limit,
                lambda sample: self._hand_over(name, sample),
                lambda exc: self._on_unreadable(name, UNDECODABLE, f"{type(exc).__name__}: {exc}"),
                self._dds_error,
            )
        except Exception as exc:  # the C take failed (the reader is being deleted, ...)
            self._take_failed(name, exc)

    def _hand_over(self, name: str, sample: Any) -> None:
        """A sample with data to ``on_message``; one without (a writer that went away
        disposed or unregistered its instance) is only counted: it is no message, and
        a topic goes stale by its age, not by its publisher leaving."""
        if isinstance(sample, self._invalid_sample):
            self.without_data[name] += 1
        else:
            self._on_message(name, sample)

    def _take_failed(self, name: str, exc: Exception) -> None:
        """Log a failed take at WARNING, at most once a minute per topic."""
        now = time.monotonic()
        with self._failures_lock:
            last = self._failures_logged.get(name)
            if last is not None and now - last < LOG_EVERY_S:
                return
            self._failures_logged[name] = now
        log.warning("%s: taking samples from DDS failed: %s: %s", name, type(exc).__name__, exc)

    def close(self) -> None:
        self.readers.clear()
        self.participant = None


class DdsSource:
    """Readers on the robot's DDS domain; Cyclone's threads deliver every-message
    topics, and the sampler takes the state topics at each tick."""

    keeps_time = False
    clock = None

    def __init__(self, options: SourceOptions) -> None:
        self._options = options
        self._readers: DdsReaders | None = None
        self._field_types: FieldTypes | None = None

    def start(self, feed: Feed) -> None:
        self._readers = DdsReaders(
            self._options.topics,
            feed.on_message,
            self._options.dds_domain_id,
            self._options.dds_localhost_only,
            self._options.extra_topics,
            self._options.dds_cyclonedds_uri,
            feed.on_unreadable,
        )

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Cyclone's own threads read the network: only stay alive and say so."""
        while not stop.wait(1.0):
            beat()

    def before_tick(self) -> None:
        if self._readers is not None:
            self._readers.take_latest()

    def stop(self) -> None:
        if self._readers is not None:
            self._readers.close()

    def finished(self) -> Finished | None:
        return None

    def field_types(self, msg: Any) -> Mapping[str, str]:
        from phytrace_edge.ingest.sources.dds_dynamic import fielddefs

        if self._field_types is None:
            self._field_types = rosbags_field_types(fielddefs())
        return self._field_types(msg)

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        if self._readers is None:
            return {}
        stats: dict[str, dict[str, Any]] = {
            name: {"without_data": count} for name, count in self._readers.without_data.items()
        }
        for name, reason in self._readers.skipped.items():
            stats[name] = {"skipped": reason}
        return stats
