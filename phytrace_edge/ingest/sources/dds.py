"""The ROS-free input (``BRIDGE_INPUT=dds``): hear a ROS 2 robot over Cyclone DDS
without ROS installed (the ``dds`` extra, PyPI ``cyclonedds``).

It reads ROS 2's own environment so it lands on the same DDS domain as the robot:
``ROS_DOMAIN_ID`` picks the domain, and ``ROS_LOCALHOST_ONLY=1`` or
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` confine it to loopback, as rmw_cyclonedds
does (a participant with Cyclone's defaults would see nothing of a localhost-only
robot). It hears Fast DDS publishers (ROS 2's default middleware) as well as
Cyclone ones: see ``domain_config``. Its readers follow the ``ros`` input's QoS rules
(``ingest.qos``): the topics where every message counts are read reliably from the
start (a one-shot diagnostics ERROR written the moment its writer matched is not
lost), and once a second the domain's writers are looked at (``dds_graph``): a topic
is read with the QoS that matches every writer of it (a best-effort sensor, a latched
goal written before the bridge started), and ``status`` shows its writers and QoS.

State topics (odometry, IMU, scan, ...) publish far faster than events are built and
only their latest value counts: their readers keep one sample, in Cyclone's C cache,
and ``take_latest`` deserialises it at the sample tick, so Python touches at most one
message per topic per tick instead of every message (an IMU at 200 Hz); its age is
the writer's stamp, bounded by the time since the previous take. Topics where every
message counts (diagnostics, goals, delivery status) are delivered as they come.
So are an incident's trigger topics (``SourceOptions.every_message``, from the
INCIDENT_* settings; none when INCIDENT_RECORDING=false): read by a listener, keeping
up to 100 samples, and never also taken at the tick. The state topics an incident's
window needs at full rate (``SourceOptions.full_rate``) keep up to FULL_RATE_DEPTH
samples, all taken at the tick, oldest first, each with its age: a listener's call
costs more than the sample. Both still match their QoS as a state stream's (best effort
before their writers are known, so a best-effort sensor matches).
The topics of ``TOPICS_EXTRA`` are read like state topics, but taken only when due
(their ``rate_hz``; delivered as they come when named in ``every_message``), with
types made from ROS 2 Jazzy's message definitions (``dds_dynamic.py``, which needs
rosbags); one whose type is not given or not known, or when rosbags is not installed,
is skipped, with the reason in the log and in ``status``.

A sample that cannot be decoded (a string that is not UTF-8: cyclonedds decodes
strictly) costs only itself: samples are taken one at a time, and that one is counted
as its topic's reject ``undecodable``, as the bag input counts such a record.

The readers are ``dds_readers.py``, what they know of the graph ``dds_graph.py``, the
wire's names, the domain's configuration and the take loop ``dds_wire.py``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from phytrace_edge.ingest.dispatch import Take
from phytrace_edge.ingest.generic import FieldTypes, rosbags_field_types
from phytrace_edge.ingest.sources.base import Feed, Finished, SourceOptions, always_due
from phytrace_edge.ingest.sources.dds_readers import DdsReaders
from phytrace_edge.ingest.sources.dds_wire import (
    UNDECODABLE,
    dds_topic_name,
    domain_config,
    take_each,
)

# the wire's names and the domain's configuration, where the tools and tests find them
__all__ = ["UNDECODABLE", "DdsSource", "dds_topic_name", "domain_config", "take_each"]

GRAPH_CHECK_S = 1.0  # how often the domain's writers are looked at


class DdsSource:
    """Readers on the robot's DDS domain; Cyclone's threads deliver every-message
    topics (and the state topics named in ``every_message``), and the sampler takes
    the other state topics at each tick (all the samples of those in ``full_rate``)."""

    keeps_time = False
    clock = None

    def __init__(self, options: SourceOptions) -> None:
        self._options = options
        self._readers: DdsReaders | None = None
        self._field_types: FieldTypes | None = None
        self._due: Callable[[str], bool] = always_due

    def start(self, feed: Feed) -> None:
        self._due = feed.due
        self._readers = DdsReaders(
            self._options.topics,
            feed.on_message,
            self._options.dds_domain_id,
            self._options.dds_localhost_only,
            self._options.extra_topics,
            self._options.dds_cyclonedds_uri,
            feed.on_unreadable,
            self._options.qos_overrides,
            self._options.every_message,
            self._options.full_rate,
        )

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Cyclone's own threads read the network: look at the domain's writers now
        and then (QoS matching, ``status``'s publishers), and say it is alive."""
        while True:
            if self._readers is not None:
                self._readers.refresh()
            beat()
            if stop.wait(GRAPH_CHECK_S):
                return

    def before_tick(self) -> Sequence[Take]:
        return self._readers.take_latest(self._due) if self._readers is not None else []

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
        stats = self._readers.stats()
        for name, count in self._readers.without_data.items():
            stats[name] = {**stats.get(name, {}), "without_data": count}
        for name, reason in self._readers.skipped.items():
            stats[name] = {"skipped": reason}
        return stats
