"""UDMBuilder: the latest reading of each topic in, one UDM event per ``build`` (a
sample tick, ``sampler.py``) out.

Handler callbacks may arrive on any thread (rclpy multi-threaded executors, the DDS
listener thread); ``add_reading`` and ``build`` are serialised by one lock, and the
event itself is assembled outside it (``assemble.py``, a pure function) from an atomic
snapshot. Between two ticks the builder also keeps what must not vanish before the
next event takes it: the trackers below (diagnostics statuses, delivery transitions,
goals).

Besides the one ``telemetry.periodic`` event, a tick takes the side events that came
in since the last one (``side_events``): ``log.record`` from ``/rosout``
(``log_records.py``) and ``telemetry.topic`` from ``TOPICS_EXTRA`` (``topic_events.py``).

Each event is built with its class (docs/udm.md, "Event classes"): *important* when it
carries something that must never be thinned from a backlog (a diagnostics status
entering or leaving ERROR/STALE, a delivery or task transition, a new goal, or the
first data after the start or after a gap longer than STALE_AFTER_S), else
*periodic*. The class travels beside the event into the queue (``Built``), not in the
UDM event.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

from phytrace_edge.builder.assemble import Latest, Snapshot, assemble_event, is_fresh
from phytrace_edge.builder.log_records import LogRecords, log_event
from phytrace_edge.builder.options import BuilderOptions
from phytrace_edge.builder.topic_events import TopicEvents, topic_event
from phytrace_edge.ingest.generic import FieldTypes, rosidl_field_types
from phytrace_edge.ingest.readings import (
    DeliveryStatusReading,
    DiagnosticsReading,
    DiagnosticStatusFields,
    GoalReading,
    LogReading,
    Reading,
)
from phytrace_edge.ingest.topics import DOMAINS
from phytrace_edge.udm.event import format_timestamp, new_event_id
from phytrace_edge.udm.types import Built, UdmEvent, UdmIdentity

MAX_ITEMS_PER_EVENT = 256
_SEVERITY = {"unknown": 0, "warn": 1, "stale": 2, "error": 3}
_ALARM_LEVELS = ("error", "stale")


# ---------------------------------------------------------------- between two ticks
# What happens between two sample ticks and must not vanish: a diagnostics ERROR that
# lasts 50 ms, a delivery that goes ``arriving -> delivered -> returning`` within one
# tick, two goals sent in a row. Each is kept by a tracker until the next event takes
# it. The trackers are plain state machines; the builder serialises calls.


@dataclass
class DiagnosticsTracker:
    """Non-OK diagnostic statuses: those active now, and those seen since the last event.

    A status is keyed by (hardware_id, name). It is *active* while its latest level is
    not OK. Every non-OK status observed since the last ``take`` is reported once even
    if it has cleared since, with the worst level seen and how often it was seen.
    """

    active: dict[tuple[str, str], DiagnosticStatusFields] = field(default_factory=dict)
    pending: dict[tuple[str, str], dict[str, Any]] = field(default_factory=dict)
    alarming: set[tuple[str, str]] = field(default_factory=set)  # at ERROR or STALE now
    alarm_changed: bool = False  # a status entered or left ERROR/STALE since the last take

    def observe(self, statuses: list[DiagnosticStatusFields], at_wall_s: float) -> None:
        for status in statuses:
            key = (status.get("hardware_id", ""), status["name"])
            self._note_alarm(key, status["level"] in _ALARM_LEVELS)
            if status["level"] == "ok":
                self.active.pop(key, None)
                continue
            self.active[key] = status
            seen = self.pending.get(key)
            if seen is None:
                if len(self.pending) >= MAX_ITEMS_PER_EVENT:
                    continue
                seen = {**status, "occurrences": 0, "first_seen_at": format_timestamp(at_wall_s)}
                self.pending[key] = seen
            worst = max(seen["level"], status["level"], key=_SEVERITY.__getitem__)
            seen.update(status, level=worst)
            seen["occurrences"] += 1

    def _note_alarm(self, key: tuple[str, str], alarm: bool) -> None:
        if alarm != (key in self.alarming):
            self.alarm_changed = True
            if alarm:
                self.alarming.add(key)
            else:
                self.alarming.discard(key)

    def take_alarm_change(self) -> bool:
        """Whether a status entered or left ERROR/STALE since the last call."""
        changed, self.alarm_changed = self.alarm_changed, False
        return changed

    def take(self, include_active: bool) -> list[dict[str, Any]]:
        """Errors for the next event; clears what was seen since the last one.

        ``include_active`` is False when /diagnostics has gone stale: its last word is
        then no longer reported as the current state.
        """
        errors = []
        for key, seen in self.pending.items():
            errors.append({**seen, "active": include_active and key in self.active})
        if include_active:
            for key, status in self.active.items():
                if key not in self.pending:
                    errors.append({**status, "active": True})
        self.pending = {}
        return errors[:MAX_ITEMS_PER_EVENT]


@dataclass
class TransitionTracker:
    """Task/delivery state changes seen on /delivery/status since the last event."""

    last_state: str | None = None
    last_task: str | None = None
    pending: list[dict[str, Any]] = field(default_factory=list)

    def observe(self, reading: DeliveryStatusReading, at_wall_s: float) -> None:
        payload = reading.get("payload", {})
        task = reading.get("task", {})
        state = payload.get("delivery_state") or task.get("status")
        task_id = task.get("task_id")
        if state is None or (state == self.last_state and task_id == self.last_task):
            return
        transition = {"at": format_timestamp(at_wall_s), "to": state}
        if task_id is not None:
            transition["task_id"] = task_id
        if self.last_state is not None:
            transition["from"] = self.last_state
        self.last_state, self.last_task = state, task_id
        if len(self.pending) < MAX_ITEMS_PER_EVENT:
            self.pending.append(transition)

    def take(self) -> list[dict[str, Any]]:
        taken, self.pending = self.pending, []
        return taken


@dataclass
class GoalTracker:
    """Goals received since the last event (the latest is also the current goal).

    A goal with the stamp and pose of the previous one is that goal again, not a new
    one: a latched goal replayed to a subscription re-created as transient-local."""

    pending: list[dict[str, Any]] = field(default_factory=list)
    last_key: tuple[Any, ...] | None = None

    def observe(self, reading: GoalReading, at_wall_s: float) -> None:
        goal = reading.get("goal")
        if goal is None:
            return
        key = (reading.get("stamp_ns"), *sorted(goal.items()))
        if key == self.last_key:
            return
        self.last_key = key
        if len(self.pending) < MAX_ITEMS_PER_EVENT:
            self.pending.append({**goal, "received_at": format_timestamp(at_wall_s)})

    def take(self) -> list[dict[str, Any]]:
        taken, self.pending = self.pending, []
        return taken


# ---------------------------------------------------------------- the builder


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
    def identity(self) -> UdmIdentity:
        """The UDM ``identity`` of this robot."""
        return self._identity.copy()

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

    def _mark_clock(self, event: UdmEvent) -> None:
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
