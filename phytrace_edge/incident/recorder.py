"""IncidentRecorder: the flight recorder. Readings in, incidents out.

Every reading of a window topic goes into the ring (``ring.py``); every reading of a
watched topic goes past the trigger rules (``triggers.py``). A trigger opens an
incident whose window runs from INCIDENT_BEFORE_S before it to INCIDENT_AFTER_S after
it; a trigger inside an open window extends it (at most INCIDENT_MAX_S past the first
trigger). Incidents are rate-limited: at most INCIDENT_MAX_PER_HOUR open in any hour;
a trigger beyond that is counted (``rate_limited``), not recorded.

Time is the input's timeline, from the same clock as the builder's: a live input's
monotonic clock for the window's arithmetic (a wall clock step cannot stretch or end a
window) and its wall clock for stamps; a bag's time for both, so a replay gives the
same incidents at any REPLAY_RATE. A window closes at the first sample tick
(``take_closed``) more than ``settle_s`` past its end, and at a stop (``close_now``: the
incident is kept, marked ``cut_short`` if its end had not come). ``settle_s`` is for
the live inputs, which take the window topics' messages at the tick: a message
received before the end may reach the recorder a tick later, after one of another
topic received after it; a bag's messages come in time order (0).

Readings come on the ingest threads, marks from the CLI's poller or the ROS service,
``take_closed`` from the sample tick: one lock serialises them, and a closed incident
is turned into events outside it.
"""

from __future__ import annotations

import threading
from collections import Counter, deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from phytrace_edge.incident.figures import IncidentFigures
from phytrace_edge.incident.options import IncidentOptions
from phytrace_edge.incident.parts import ClosedIncident, Sample, incident_events, incident_id
from phytrace_edge.incident.ring import WindowRing
from phytrace_edge.incident.triggers import Trigger, TriggerRules, shortened
from phytrace_edge.udm.types import Built, UdmIdentity

HOUR_S = 3600.0
Outcome = Literal["opened", "extended", "rate_limited", "off"]


class Clock(Protocol):
    def monotonic(self) -> float: ...

    def wall(self) -> float: ...


@dataclass(frozen=True)
class Marked:
    """What became of a trigger: ``opened`` a new incident (its id), ``extended`` the
    open one (its id), ``rate_limited`` or ``off`` (recording is off)."""

    outcome: Outcome
    incident_id: str | None = None


@dataclass
class _Open:
    trigger: Trigger
    start_s: float
    end_s: float
    triggers: int = 1
    dropped: Counter[str] = field(default_factory=Counter)


class IncidentRecorder:
    """See the module doc; ``counts`` and ``samples_dropped`` are for ``status``."""

    def __init__(
        self,
        options: IncidentOptions,
        identity: UdmIdentity,
        max_part_bytes: int,
        clock: Clock,
        unsynchronized: Callable[[], bool] | None = None,
        settle_s: float = 0.0,
    ) -> None:
        """``unsynchronized`` says whether the wall clock that stamps incidents is not
        synchronized now (None: the stamps are not this machine's, as a bag's);
        ``settle_s``, how late a reading can come after one received later."""
        self._settle_s = settle_s
        self.options = options
        self._unsynchronized = unsynchronized
        self._identity = identity
        self._max_part_bytes = max_part_bytes
        self._clock = clock
        self._ring = WindowRing(options.buffer_max_bytes)
        self._rules = TriggerRules(
            options.diagnostics_level, options.rosout_level, options.conditions
        )
        self.window_topics = frozenset(options.topics) if options.enabled else frozenset()
        self.watched = self.window_topics | (self._rules.topics() if options.enabled else set())
        self._lock = threading.Lock()
        self._open: _Open | None = None
        self._opened_at: deque[float] = deque()  # when incidents opened, the last hour
        self._closed: list[ClosedIncident] = []
        self.counts: Counter[str] = Counter()

    # ------------------------------------------------------------------ in

    def observe(self, topic: str, reading: Mapping[str, Any], age_s: float = 0.0) -> None:
        """A reading of ``topic`` (or an extra topic's message data), received
        ``age_s`` ago on the input's timeline."""
        if topic not in self.watched:
            return
        at_s = self._clock.monotonic() - age_s
        wall_s = self._clock.wall() - age_s
        with self._lock:
            if topic in self.window_topics:
                evicted = self._ring.add(topic, reading, at_s)
                if evicted and self._open is not None:
                    self._open.dropped.update(
                        s.topic for s in evicted if s.at_s >= self._open.start_s
                    )
            for trigger in self._rules.observe(topic, reading, at_s, wall_s):
                self._fire(trigger)
            self._forget(at_s)

    def mark(self, reason: str, at_wall_s: float | None = None) -> Marked:
        """A trigger by hand (``phytrace-edge mark``, the ``~/mark`` service), at
        ``at_wall_s`` on the wall clock (default: now)."""
        if not self.options.enabled:
            return Marked("off")
        now_s, now_wall = self._clock.monotonic(), self._clock.wall()
        wall_s = now_wall if at_wall_s is None else min(at_wall_s, now_wall)
        trigger = Trigger("manual", shortened(reason), now_s - (now_wall - wall_s), wall_s)
        with self._lock:
            outcome = self._fire(trigger)
            opened = self._open
            self._forget(now_s)
        if opened is None or outcome == "rate_limited":
            return Marked(outcome)
        return Marked(outcome, incident_id(self._identity, opened.trigger))

    def _fire(self, trigger: Trigger) -> Outcome:
        self.counts["triggers"] += 1
        current = self._open
        if current is not None and trigger.at_s <= current.end_s:
            latest_end = current.trigger.at_s + self.options.max_s
            current.end_s = max(current.end_s, min(trigger.at_s + self.options.after_s, latest_end))
            current.triggers += 1
            self.counts["extended"] += 1
            return "extended"
        while self._opened_at and self._opened_at[0] <= trigger.at_s - HOUR_S:
            self._opened_at.popleft()
        if len(self._opened_at) >= self.options.max_per_hour:
            self.counts["rate_limited"] += 1
            return "rate_limited"
        if current is not None:  # past its end, not closed yet: close it first
            self._close(current, current.end_s, cut_short=False)
        self._opened_at.append(trigger.at_s)
        self._open = _Open(
            trigger, trigger.at_s - self.options.before_s, trigger.at_s + self.options.after_s
        )
        self.counts["opened"] += 1
        return "opened"

    # ------------------------------------------------------------------ out

    def take_closed(self) -> list[Built]:
        """The incidents whose window ended by now, as important events (called at
        every sample tick)."""
        with self._lock:
            if self._open is not None or self._closed:
                self._advance(self._clock.monotonic())
            closed, self._closed = self._closed, []
        return self._events(closed)

    def close_now(self) -> list[Built]:
        """At a stop: the open incident, closed now (``cut_short``), and any waiting."""
        with self._lock:
            now_s = self._clock.monotonic()
            self._advance(now_s)
            if self._open is not None:
                end_s = self._open.end_s
                self._close(self._open, min(now_s, end_s), cut_short=now_s < end_s)
            closed, self._closed = self._closed, []
        return self._events(closed)

    def _advance(self, now_s: float) -> None:
        """Close the open window once ``now_s`` is settled past its end (strictly: a
        reading received at the very end is in it)."""
        current = self._open
        if current is not None and now_s > current.end_s + self._settle_s:
            self._close(current, current.end_s, cut_short=False)
        self._forget(now_s)

    def _forget(self, now_s: float) -> None:
        """Let the ring's samples go that no window can want any more."""
        horizon = now_s - self.options.before_s - self._settle_s
        current = self._open
        self._ring.forget_before(horizon if current is None else min(horizon, current.start_s))

    def _close(self, current: _Open, end_s: float, cut_short: bool) -> None:
        """Every time of the incident is said on the wall clock as it is at the close,
        from the timeline (``at_s``): a wall-clock step during the window (a robot's
        first NTP sync) cannot leave part of it years off, and the incident's stamps
        agree with the events queued beside it (repaired as they are, docs/udm.md)."""
        offset = self._clock.wall() - self._clock.monotonic()
        samples = [
            Sample(s.topic, offset + s.at_s, s.json)
            for s in self._ring.between(current.start_s, end_s)
        ]
        self._closed.append(
            ClosedIncident(
                trigger=current.trigger,
                start_s=current.start_s,
                end_s=end_s,
                start_wall_s=offset + current.start_s,
                end_wall_s=offset + end_s,
                samples=samples,
                triggers=current.triggers,
                dropped=dict(current.dropped),
                cut_short=cut_short,
                trigger_at_wall_s=offset + current.trigger.at_s,
            )
        )
        self._open = None
        self.counts["recorded"] += 1
        if cut_short:
            self.counts["cut_short"] += 1

    def _events(self, closed: Iterable[ClosedIncident]) -> list[Built]:
        built = []
        unsynchronized = self._unsynchronized is not None and self._unsynchronized()
        for incident in closed:
            parts = incident_events(self._identity, incident, self._max_part_bytes)
            if unsynchronized:  # as every event: a later step repairs it (docs/udm.md)
                for part in parts:
                    part["wall_clock"] = {"synchronized": False}
            self.counts["parts"] += len(parts)
            built += [Built(event, important=True) for event in parts]
        return built

    # ------------------------------------------------------------------ figures

    def figures(self) -> IncidentFigures:
        """What ``status`` shows of the recorder (this run's counts)."""
        with self._lock:
            counts = self.counts
            return IncidentFigures(
                enabled=self.options.enabled,
                recording=self._open is not None,
                window_topics=sorted(self.window_topics),
                buffer_bytes=self._ring.bytes,
                buffer_max_bytes=self._ring.max_bytes,
                buffer_samples=len(self._ring),
                samples_dropped=sum(self._ring.dropped.values()),
                triggers=counts["triggers"],
                opened=counts["opened"],
                extended=counts["extended"],
                rate_limited=counts["rate_limited"],
                recorded=counts["recorded"],
                cut_short=counts["cut_short"],
                parts=counts["parts"],
            )
