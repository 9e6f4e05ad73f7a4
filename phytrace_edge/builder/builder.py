"""UDMBuilder: keeps the latest reading per topic and builds one event per sample tick.

Handler callbacks may arrive on any thread (rclpy multi-threaded executors, the DDS
listener thread); ``add_reading`` and ``build`` are serialised by one lock, and the
event itself is assembled outside it from an atomic snapshot.

Besides the one ``telemetry.periodic`` event, a tick takes the side events that came
in since the last one (``side_events``): ``log.record`` from ``/rosout``
(``log_records.py``) and ``telemetry.topic`` from ``TOPICS_EXTRA`` (``topic_events.py``).

Each event is built with its class (docs/udm.md, "Event classes"): *important* when it
carries something that must never be thinned from a backlog (a diagnostics status
entering or leaving ERROR/STALE, a delivery or task transition, a new goal, or the
first data after the start or after a gap longer than STALE_AFTER_S), else
*periodic*. The class travels beside the event into the queue, not in the UDM event.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol, cast

from phytrace_edge.builder.accumulate import DiagnosticsTracker, GoalTracker, TransitionTracker
from phytrace_edge.builder.assemble import Latest, Snapshot, assemble_event, is_fresh
from phytrace_edge.builder.log_records import LogRecords, log_event
from phytrace_edge.builder.options import BuilderOptions
from phytrace_edge.builder.topic_events import TopicEvents, topic_event
from phytrace_edge.ingest.generic import FieldTypes, rosidl_field_types
from phytrace_edge.ingest.readings import (
    DeliveryStatusReading,
    DiagnosticsReading,
    GoalReading,
    LogReading,
    Reading,
)
from phytrace_edge.ingest.topics import DOMAINS
from phytrace_edge.udm.event import new_event_id


class Clock(Protocol):
    """Time as the builder sees it: a monotonic clock for ages, a wall clock for stamps."""

    def monotonic(self) -> float: ...

    def wall(self) -> float: ...


class SystemClock:
    """The process's own clocks."""

    def monotonic(self) -> float:
        return time.monotonic()

    def wall(self) -> float:
        return time.time()


class Built(NamedTuple):
    """One tick's event and its class."""

    event: dict[str, Any]
    important: bool


class UDMBuilder:
    """Latest values in, one UDM event per ``build`` call (a sample tick) out."""

    def __init__(
        self,
        options: BuilderOptions,
        clock: Clock | None = None,
        field_types: FieldTypes = rosidl_field_types,
        unsynchronized: Callable[[], bool] | None = None,
    ) -> None:
        """``field_types`` describes the input's messages (``ingest.generic``);
        ``unsynchronized`` says whether the wall clock that stamps events is not
        synchronized now (None: the stamps are not this machine's, as a bag's)."""
        self._unsynchronized = unsynchronized
        self._identity = options.identity.as_dict()
        self._stale_after_s = options.stale_after_s
        self._use_sim_time = options.use_sim_time
        self._clock = clock or SystemClock()
        self._lock = threading.Lock()
        self._latest: dict[str, Latest] = {}
        # when each topic's latest message was received, /rosout and the extra topics
        # included (``status``'s last_seen_age_s)
        self._received_mono: dict[str, float] = {}
        self._diagnostics = DiagnosticsTracker()
        self._transitions = TransitionTracker()
        self._goals = GoalTracker()
        self._last_data_mono: float | None = None  # when the last event with data was built
        self.stale_omissions: Counter[str] = Counter()
        self.logs = LogRecords(options.rosout_min_level, options.rosout_burst)
        self.extra = TopicEvents(options.extra_topics, field_types, options.extra_max_array)
        # What the every-message topics accumulate between two ticks (besides their
        # latest reading); tests/unit/test_builder.py holds this to the topic table.
        self.accumulators: dict[str, Callable[[Any, float], None]] = {
            "/diagnostics": self._observe_diagnostics,
            "/delivery/status": self._observe_delivery,
            "/goal_pose": self._observe_goal,
        }

    def _observe_diagnostics(self, reading: DiagnosticsReading, now_wall: float) -> None:
        self._diagnostics.observe(reading.get("statuses", []), now_wall)

    def _observe_delivery(self, reading: DeliveryStatusReading, now_wall: float) -> None:
        self._transitions.observe(reading, now_wall)

    def _observe_goal(self, reading: GoalReading, now_wall: float) -> None:
        self._goals.observe(reading, now_wall)

    @property
    def identity(self) -> dict[str, str]:
        """The UDM ``identity`` of this robot."""
        return dict(self._identity)

    def add_reading(self, topic: str, reading: Reading, age_s: float = 0.0) -> None:
        """Record ``reading`` as the latest of ``topic`` (a canonical topic name),
        received ``age_s`` ago (a message taken at the tick waited for it); a
        ``/rosout`` record becomes a log record of its own."""
        now_mono, now_wall = self._clock.monotonic(), self._clock.wall()
        received = now_mono - age_s
        with self._lock:
            self._received_mono[topic] = received
        if topic == "/rosout":
            self.logs.observe(cast(LogReading, reading), now_mono)
            return
        with self._lock:
            self._latest[topic] = Latest(reading, received)
            accumulate = self.accumulators.get(topic)
            if accumulate is not None:
                accumulate(reading, now_wall)

    def add_message(self, topic: str, msg: Any, age_s: float = 0.0) -> None:
        """A message of a ``TOPICS_EXTRA`` topic (any type), received ``age_s`` ago."""
        if self.extra.wants(topic):
            now_mono = self._clock.monotonic()
            with self._lock:
                self._received_mono[topic] = now_mono - age_s
            self.extra.offer(topic, msg, now_mono, now_mono - age_s)

    def extra_due(self, topic: str) -> bool:
        """Whether a ``TOPICS_EXTRA`` topic is due now (its ``rate_hz``): an input that
        takes messages at the tick takes this topic's only then (``Feed.due``)."""
        return self.extra.due(topic, self._clock.monotonic())

    def side_events(self, captured_at_s: float | None = None) -> list[Built]:
        """The log records and extra-topic events that came in since the last call.
        Log records and on-change samples are important; sampled topics periodic."""
        now_mono = self._clock.monotonic()
        captured_at = self._clock.wall() if captured_at_s is None else captured_at_s
        sim = self._use_sim_time
        built = [
            Built(log_event(self._identity, record, captured_at, sim), True)
            for record, _ in self.logs.take()
        ]
        for sample in self.extra.take(now_mono):
            event = topic_event(self._identity, sample, captured_at, now_mono, sim)
            built.append(Built(event, sample.mode == "on_change"))
        if captured_at_s is None:
            for side_event, _ in built:
                self._mark_clock(side_event)
        return built

    def _mark_clock(self, event: dict[str, Any]) -> None:
        """Stamped on this machine's wall clock while the kernel does not call it
        synchronized: say so, so that a later step can repair it (docs/udm.md, "Time")."""
        if self._unsynchronized is not None and self._unsynchronized():
            event["wall_clock"] = {"synchronized": False}

    def side_counts(self) -> dict[str, dict[str, int]]:
        """What became of /rosout records and extra-topic messages, per topic."""
        logs = {
            what: self.logs.counts[what] for what in ("records", "suppressed", "below_level", "own")
        }
        return {"/rosout": logs, **self.extra.stats()}

    def build(self, captured_at_s: float | None = None) -> Built:
        """The event for this tick and its class (see the module doc); ``captured_at_s``
        overrides the wall clock (a replay's timeline)."""
        now_mono = self._clock.monotonic()
        captured_at = self._clock.wall() if captured_at_s is None else captured_at_s
        with self._lock:
            latest = dict(self._latest)
            fresh = {t: is_fresh(t, v, now_mono, self._stale_after_s) for t, v in latest.items()}
            self.stale_omissions.update(topic for topic, ok in fresh.items() if not ok)
            snapshot = Snapshot(
                latest=latest,
                errors=self._diagnostics.take(include_active=fresh.get("/diagnostics", False)),
                transitions=self._transitions.take(),
                new_goals=self._goals.take(),
            )
            alarm_changed = self._diagnostics.take_alarm_change()
            last_data, gap = self._last_data_mono, False
        event = assemble_event(
            self._identity,
            snapshot,
            event_id=new_event_id(int(captured_at * 1000)),
            captured_at_s=captured_at,
            now_mono_s=now_mono,
            stale_after_s=self._stale_after_s,
            use_sim_time=self._use_sim_time,
        )
        if captured_at_s is None:
            self._mark_clock(event)
        if any(domain in event for domain in DOMAINS):
            gap = last_data is None or now_mono - last_data > self._stale_after_s
            with self._lock:
                self._last_data_mono = now_mono
        important = gap or alarm_changed or bool(snapshot.transitions or snapshot.new_goals)
        return Built(event, important)

    def topic_ages(self) -> dict[str, float]:
        """Seconds since each topic's latest message was received (the table's,
        /rosout's and the extra topics')."""
        now = self._clock.monotonic()
        with self._lock:
            return {
                topic: round(max(0.0, now - received), 3)
                for topic, received in self._received_mono.items()
            }

    def topics_seen(self) -> list[str]:
        """Topics that delivered at least one reading, sorted."""
        with self._lock:
            return sorted(self._latest)
