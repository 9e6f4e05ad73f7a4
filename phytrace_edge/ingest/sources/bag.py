"""Replay a recorded bag through the bridge (``BRIDGE_INPUT=bag:PATH``): backfill a
robot's history into PhyCloud, or test with real data.

rosbags reads rosbag2 ``.mcap`` and ``.db3`` bags and ROS 1 ``.bag`` files with the
Jazzy message definitions (the only module that imports it; it is the ``bag`` extra).
Messages go through the same handlers in bag time order, and events are built on the
bag's timeline: ``captured_at`` is bag time, and staleness is measured in bag time.
``rate`` 1.0 replays at recorded speed, 2.0 twice as fast, 0 as fast as possible.

A record that cannot be decoded (a string that is not UTF-8, which rosbags refuses
with ``UnicodeDecodeError``) is skipped and counted as its topic's reject
``undecodable``; the replay goes on. Only an unreadable bag (truncated, damaged)
stops it early.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import Take
from phytrace_edge.ingest.generic import rosbags_field_types
from phytrace_edge.ingest.sources.base import Feed, Finished, SourceOptions
from phytrace_edge.ingest.topics import TOPIC_BY_NAME

log = logging.getLogger(__name__)

NS = 1_000_000_000
GAP_S = 30.0  # a pause in the bag longer than this is skipped, not ticked through
UNDECODABLE = "undecodable"  # the reject reason of a record rosbags cannot decode


class BagClock:
    """The builder's clock during a replay: both clocks read bag time."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def monotonic(self) -> float:
        return self.now_s

    def wall(self) -> float:
        return self.now_s


@dataclass
class ReplaySummary:
    path: str
    messages: Counter[str] = field(default_factory=Counter)
    skipped: Counter[str] = field(default_factory=Counter)
    undecodable: Counter[str] = field(default_factory=Counter)  # by topic, in ``messages``
    events: int = 0
    gaps: int = 0
    longest_gap_s: float = 0.0
    stopped: bool = False
    error: str | None = None

    def describe(self) -> str:
        read = ", ".join(f"{topic} {n}" for topic, n in sorted(self.messages.items())) or "none"
        skipped = ", ".join(f"{what} {n}" for what, n in sorted(self.skipped.items())) or "none"
        text = (
            f"replayed {self.path}: {sum(self.messages.values())} messages ({read}); "
            f"{self.events} events built; skipped: {skipped}"
        )
        if self.undecodable:
            by_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.undecodable.items()))
            text += (
                f"; {sum(self.undecodable.values())} undecodable message(s) skipped ({by_topic})"
            )
        if self.gaps:
            text += f"; {self.gaps} gap(s) skipped, the longest {self.longest_gap_s:.0f} s"
        if self.stopped:
            text += "; stopped before the end"
        return text + (f"; stopped early: {self.error}" if self.error else "")


def open_reader(path: str) -> Any:
    """An open rosbags AnyReader; a clear ConfigError when it cannot be."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError(
            "BRIDGE_INPUT=bag: needs rosbags (pip install 'phytrace-edge[bag]')"
        ) from None
    if not Path(path).exists():
        raise ConfigError(f"BRIDGE_INPUT='bag:{path}': no such file or directory")
    try:
        reader = AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as exc:  # rosbags raises its own errors for what is not a bag
        reason = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
        raise ConfigError(
            f"BRIDGE_INPUT='bag:{path}': not a readable rosbag2 or ROS 1 bag ({reason})"
        ) from None
    return reader


def replay(
    path: str,
    topics: Mapping[str, str],
    extras: Mapping[str, tuple[str, str]],
    feed: Feed,
    clock: BagClock,
    rate: float,
    stop: threading.Event,
    beat: Callable[[], None] = lambda: None,
) -> ReplaySummary:
    """Feed the bag's messages to ``feed.on_message`` and call ``feed.tick(bag_time_s)``
    every sample period of bag time; stops at the end of the bag, at ``stop``, or where
    the bag cannot be read on (reported in the summary, never raised). A record that
    cannot be decoded is skipped and given to ``feed.on_unreadable``. ``extras``
    (TOPICS_EXTRA: name -> (actual, type or "")) are read with the bag's own types."""
    summary = ReplaySummary(path)
    reader = open_reader(path)
    canonical = {actual: name for name, actual in topics.items()}
    canonical.update({actual: name for name, (actual, _) in extras.items()})
    wanted = []
    for connection in reader.connections:
        name = canonical.get(connection.topic)
        if name is not None and _reads(name, connection.msgtype, extras):
            wanted.append(connection)
        else:
            summary.skipped[f"{connection.topic} ({connection.msgtype})"] += connection.msgcount
    period_ns = int(feed.sample_period_s * NS)
    gap_ns = int(GAP_S * NS)
    started = time.monotonic()
    first_ns: int | None = None
    last_ns = 0
    next_tick_ns = 0

    def ticks_until(limit_ns: int) -> None:
        """Tick every period up to ``limit_ns``; once a tick finds nothing fresh, no
        tick before the next message would, so the rest are skipped."""
        nonlocal next_tick_ns
        while next_tick_ns <= limit_ns and not stop.is_set():
            clock.now_s = next_tick_ns / NS
            built = feed.tick(clock.now_s)
            next_tick_ns += period_ns
            if not built:
                next_tick_ns += max(0, limit_ns - next_tick_ns) // period_ns * period_ns
                if next_tick_ns <= limit_ns:
                    next_tick_ns += period_ns
                return
            summary.events += 1

    try:
        try:
            for connection, timestamp, raw in reader.messages(connections=wanted):
                if stop.is_set():
                    break
                if first_ns is None:
                    first_ns, last_ns, next_tick_ns = timestamp, timestamp, timestamp + period_ns
                if timestamp - last_ns > gap_ns:  # the robot was off, or recording paused
                    ticks_until(last_ns + gap_ns)
                    next_tick_ns = max(next_tick_ns, timestamp)  # ticks go on from here
                    first_ns += timestamp - last_ns - gap_ns  # so does the replay's pace
                    summary.gaps += 1
                    summary.longest_gap_s = max(summary.longest_gap_s, (timestamp - last_ns) / NS)
                if rate > 0:  # keep to the recorded pace, scaled
                    due = started + (timestamp - first_ns) / NS / rate
                    if stop.wait(max(0.0, due - time.monotonic())):
                        break
                ticks_until(timestamp)
                clock.now_s = timestamp / NS
                last_ns = max(last_ns, timestamp)
                name = canonical[connection.topic]
                summary.messages[name] += 1
                msg = _decoded(reader, raw, connection.msgtype, name, summary, feed)
                if msg is not None:
                    feed.on_message(name, msg)
                beat()
            if first_ns is not None and not stop.is_set():
                ticks_until(int(clock.now_s * NS))
            summary.stopped = stop.is_set()
        finally:
            reader.close()
    except Exception as exc:  # a truncated or damaged bag: keep what was read
        summary.error = f"{type(exc).__name__}: {exc}"
        log.error(
            "bag %s is damaged or truncated after %d messages: %s",
            path,
            sum(summary.messages.values()),
            summary.error,
        )
    return summary


def _decoded(
    reader: Any, raw: bytes, msgtype: str, topic: str, summary: ReplaySummary, feed: Feed
) -> Any:
    """One record as a message, or None when it cannot be decoded: one bad record
    (a string that is not UTF-8) must not end the replay of all the others. The feed
    counts it with the topic's rejects and logs it at most once a minute; the summary
    says how many there were."""
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as exc:  # rosbags raises what its decoder met: UnicodeDecodeError, ...
        summary.undecodable[topic] += 1
        feed.on_unreadable(topic, UNDECODABLE, f"{type(exc).__name__}: {exc}")
        return None


def _reads(name: str, msgtype: str, extras: Mapping[str, tuple[str, str]]) -> bool:
    """Whether topic ``name`` is read when it carries ``msgtype``: an extra topic with
    no type given is read whatever its type."""
    if name in extras:
        return extras[name][1] in ("", msgtype)
    return msgtype in TOPIC_BY_NAME[name].type_names


class BagSource:
    """A recorded bag through the handlers, on the bag's timeline; finite."""

    keeps_time = True

    def __init__(self, options: SourceOptions) -> None:
        self._options = options
        reader = open_reader(options.bag_path)  # a missing or unreadable bag fails at start
        self._field_types = rosbags_field_types(reader.typestore.fielddefs)  # the bag's types
        reader.close()
        self.clock = BagClock()
        self._feed: Feed | None = None
        self.summary: ReplaySummary | None = None  # after run()

    def start(self, feed: Feed) -> None:
        self._feed = feed

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        """Replay the bag once; returns at its end (or at ``stop``)."""
        assert self._feed is not None, "start() first"
        options = self._options
        self.summary = replay(
            options.bag_path,
            options.topics,
            options.extra_topics,
            self._feed,
            self.clock,
            options.replay_rate,
            stop,
            beat,
        )
        # a warning when records were skipped: the log's summary of those counted above
        level = logging.WARNING if self.summary.undecodable else logging.INFO
        log.log(level, "%s", self.summary.describe())

    def field_types(self, msg: Any) -> Mapping[str, str]:
        return self._field_types(msg)

    def before_tick(self) -> Sequence[Take]:
        """The replay feeds every message itself: nothing to take at the tick."""
        return []

    def stop(self) -> None:
        """The reader is closed by the replay itself."""

    def finished(self) -> Finished | None:
        if self.summary is None:
            return None
        return Finished(self.summary.describe(), ok=self.summary.error is None)

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        return {}
