"""``telemetry.topic`` events: the topics of ``TOPICS_EXTRA``, each at its own pace.

A message is offered on the ingest thread and kept as the topic's latest. It is
converted only when the topic is due (at most ``rate_hz`` times a second): at once
when it arrives due, else at the next sample tick that finds it due, so the latest
value of a topic that went quiet is still sent. ``on_change`` sends a due message only
when its data differs from the last one sent (numbers by more than ``deadband``).
The events themselves are taken, in order, at each sample tick.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from phytrace_edge.builder.envelope import classify_stamp, envelope
from phytrace_edge.ingest.convert import stamp_ns
from phytrace_edge.ingest.generic import FieldTypes, Repairs, message_data, message_type_name
from phytrace_edge.ingest.safe_text import TEXT_REPAIRED
from phytrace_edge.ingest.topics import ExtraTopic
from phytrace_edge.udm.types import TopicEvent, TopicMode, UdmIdentity

EVENT_TYPE_TOPIC = "telemetry.topic"
READY_MAX = 10_000  # converted messages waiting for the tick; beyond, counted as dropped


@dataclass(frozen=True)
class TopicSample:
    """One converted message, waiting for the next tick."""

    topic: str
    type_name: str
    mode: TopicMode
    data: dict[str, Any]
    received_mono_s: float
    stamp_ns: int | None


class TopicEvents:
    """Rate limiting and change detection of the extra topics (see the module doc)."""

    def __init__(
        self, extras: Iterable[ExtraTopic], field_types: FieldTypes, max_array: int
    ) -> None:
        self._specs = {extra.name: extra for extra in extras}
        self._field_types, self._max_array = field_types, max_array
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[Any, float]] = {}
        self._checked_at: dict[str, float] = {}
        self._last_data: dict[str, dict[str, Any]] = {}
        self._ready: list[TopicSample] = []
        self.counts: Counter[tuple[str, str]] = Counter()  # (topic, events|unchanged|...)

    def wants(self, topic: str) -> bool:
        return topic in self._specs

    def offer(
        self, topic: str, msg: Any, now_mono_s: float, received_mono_s: float | None = None
    ) -> None:
        """Keep ``msg`` (received at ``received_mono_s``, default now) as the latest of
        ``topic``; convert it now if the topic is due."""
        with self._lock:
            self._latest[topic] = (msg, now_mono_s if received_mono_s is None else received_mono_s)
            if self._due(topic, now_mono_s):
                self._consider(topic, now_mono_s)

    def due(self, topic: str, now_mono_s: float) -> bool:
        """Whether a message of ``topic`` offered now would be converted (always, for a
        topic that is not an extra topic)."""
        if topic not in self._specs:
            return True
        with self._lock:
            return self._due(topic, now_mono_s)

    def take(self, now_mono_s: float) -> list[TopicSample]:
        """The samples to send now: those ready, and the latest of each topic now due."""
        with self._lock:
            for topic in [t for t in self._latest if self._due(t, now_mono_s)]:
                self._consider(topic, now_mono_s)
            ready, self._ready = self._ready, []
        return ready

    def stats(self) -> dict[str, dict[str, int]]:
        """Per extra topic: events made, due messages not sent (unchanged, not
        converted, dropped), and messages converted with their text repaired."""
        with self._lock:
            return {
                topic: {
                    what: self.counts[(topic, what)]
                    for what in ("events", "unchanged", "not_converted", "dropped", TEXT_REPAIRED)
                    if self.counts[(topic, what)] or what == "events"
                }
                for topic in self._specs
            }

    def _due(self, topic: str, now_mono_s: float) -> bool:
        checked = self._checked_at.get(topic)
        return checked is None or now_mono_s - checked >= 1.0 / self._specs[topic].rate_hz

    def _consider(self, topic: str, now_mono_s: float) -> None:
        msg, received = self._latest.pop(topic)
        self._checked_at[topic] = now_mono_s
        spec = self._specs[topic]
        repairs = Repairs()
        try:
            data = message_data(msg, self._field_types, self._max_array, repairs)
            type_name = spec.type_name or repairs.text(message_type_name(msg))
        except Exception:  # a message the type information does not describe
            self.counts[(topic, "not_converted")] += 1
            return
        if repairs.count:  # the message is kept, with U+FFFD where its text was broken
            self.counts[(topic, TEXT_REPAIRED)] += 1
        if spec.mode == "on_change":
            last = self._last_data.get(topic)
            if last is not None and not changed(last, data, spec.deadband):
                self.counts[(topic, "unchanged")] += 1
                return
            self._last_data[topic] = data
        if len(self._ready) >= READY_MAX:
            self.counts[(topic, "dropped")] += 1
            return
        self.counts[(topic, "events")] += 1
        header = getattr(msg, "header", None)
        stamp = stamp_ns(header) if header is not None else None
        self._ready.append(TopicSample(topic, type_name, spec.mode, data, received, stamp))


def changed(old: Any, new: Any, deadband: float) -> bool:
    """Whether ``new`` differs from ``old``: a number by more than ``deadband``, any
    other value at all, or a different shape."""
    if isinstance(old, dict) and isinstance(new, dict):
        return old.keys() != new.keys() or any(changed(old[k], new[k], deadband) for k in old)
    if isinstance(old, list) and isinstance(new, list):
        return len(old) != len(new) or any(
            changed(a, b, deadband) for a, b in zip(old, new, strict=True)
        )
    numbers = (int, float)
    if (
        isinstance(old, numbers)
        and isinstance(new, numbers)
        and not isinstance(old, bool)
        and not isinstance(new, bool)
    ):
        return abs(new - old) > deadband
    return bool(old != new)


def topic_event(
    identity: UdmIdentity,
    sample: TopicSample,
    captured_at_s: float,
    now_mono_s: float,
    use_sim_time: bool = False,
) -> TopicEvent:
    """One ``telemetry.topic`` event (docs/udm.md)."""
    return {
        **envelope(identity, EVENT_TYPE_TOPIC, captured_at_s),
        "topic": sample.topic,
        "type": sample.type_name,
        "mode": sample.mode,
        "data": sample.data,
        "age_s": round(max(0.0, now_mono_s - sample.received_mono_s), 3),
        **classify_stamp(sample.stamp_ns, captured_at_s, use_sim_time),
    }
