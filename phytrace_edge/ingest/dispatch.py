"""The one place handlers are called: message in, reading to the builder, rejects counted.

Messages come in two ways, both ending in ``on_message`` (and in ``on_unreadable`` for
one the input could not decode: a bag's record whose text is not UTF-8). A message an
input is called back with as it arrives (an every-message topic, a bag's record) it
hands to ``Dispatcher.on_message`` itself. The newest messages of the state topics,
which the ros and dds inputs take at the sample tick, the input only returns (from
``before_tick``, as ``Take`` values); the sampler hands them to ``on_taken``, then
builds the tick's event, so the input never calls the dispatcher or the builder from
inside the tick.

A message a handler rejects is counted by (topic, reason) and logged at WARNING at
most once a minute per pair, so a topic that publishes garbage at 100 Hz cannot flood
the log; it never stops the other topics. A message whose text had to be repaired
(``safe_text.py``) is kept, and counted and logged the same way under
``text_repaired``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.readings import Reading
from phytrace_edge.ingest.safe_text import TEXT_REPAIRED
from phytrace_edge.ingest.topics import TOPICS

log = logging.getLogger(__name__)

LOG_EVERY_S = 60.0


@dataclass(frozen=True)
class TakenMessage:
    """A message an input took at the sample tick: its canonical topic (or extra
    topic's name), the message, and how long ago the middleware received it
    (``sources.base.age_at_take``: the reception stamp, bounded by the wait)."""

    topic: str
    message: Any
    age_s: float


@dataclass(frozen=True)
class TakenUnreadable:
    """A sample an input took at the sample tick and could not decode (the dds input's
    ``undecodable``): counted with its topic's rejects."""

    topic: str
    reason: str
    detail: str


Take: TypeAlias = TakenMessage | TakenUnreadable


class Dispatcher:
    """Routes a message to its topic's handler and the reading to ``on_reading``; a
    message of a topic outside the table (``TOPICS_EXTRA``) goes to ``on_other`` as it
    is, to be converted generically when it is due."""

    def __init__(
        self,
        on_reading: Callable[[str, Reading, float], None],
        on_other: Callable[[str, Any, float], None] = lambda topic, msg, age_s: None,
    ) -> None:
        """``on_reading`` and ``on_other`` get the topic, the reading or message, and
        how long ago the message was received (``on_message``'s ``age_s``)."""
        self._on_reading, self._on_other = on_reading, on_other
        self._handlers = {spec.name: spec.handler for spec in TOPICS}
        self._lock = threading.Lock()
        self._last_logged: dict[tuple[str, str], float] = {}
        self.received: Counter[str] = Counter()
        self.rejected: Counter[tuple[str, str]] = Counter()

    def on_message(self, topic: str, msg: Any, age_s: float = 0.0) -> None:
        """Handle one message of canonical ``topic``, received ``age_s`` ago (a
        message taken at the sample tick waited in its subscription); never raises."""
        with self._lock:
            self.received[topic] += 1
        handler = self._handlers.get(topic)
        if handler is None:
            self._on_other(topic, msg, age_s)
            return
        try:
            reading = handler(msg)
        except MalformedMessage as exc:
            self._reject(topic, exc.reason, exc.detail)
            return
        except Exception as exc:  # a handler bug must not stop ingest of other topics
            self._reject(topic, "handler_error", f"{type(exc).__name__}: {exc}")
            return
        for field in reading.pop("rejected_fields", ()):
            self._reject(topic, f"bad_field:{field}", f"field {field!r} has a wrong type")
        repaired = reading.pop("text_repaired", 0)
        if repaired:
            self._reject(
                topic,
                TEXT_REPAIRED,
                f"{repaired} string(s) held what UTF-8 cannot (a lone surrogate): "
                "replaced by U+FFFD",
                what="text repaired, message kept",
            )
        self._on_reading(topic, reading, age_s)

    def on_taken(self, takes: Sequence[Take]) -> None:
        """What an input took at the sample tick (its ``before_tick``), handed over by
        the sampler before it builds the tick's event, in the order taken: a message
        as ``on_message`` with its age, an unreadable sample as ``on_unreadable``."""
        for take in takes:
            if isinstance(take, TakenMessage):
                self.on_message(take.topic, take.message, take.age_s)
            else:
                self.on_unreadable(take.topic, take.reason, take.detail)

    def on_unreadable(self, topic: str, reason: str, detail: str) -> None:
        """A message of canonical ``topic`` the input could not decode: received, and
        rejected for ``reason``; never raises."""
        with self._lock:
            self.received[topic] += 1
        self._reject(topic, reason, detail)

    def _reject(self, topic: str, reason: str, detail: str, what: str = "message rejected") -> None:
        now = time.monotonic()
        with self._lock:
            self.rejected[(topic, reason)] += 1
            count = self.rejected[(topic, reason)]
            last = self._last_logged.get((topic, reason))
            should_log = last is None or now - last >= LOG_EVERY_S
            if should_log:
                self._last_logged[(topic, reason)] = now
        if should_log:
            log.warning("%s: %s (%s, %d so far): %.200s", topic, what, reason, count, detail)
