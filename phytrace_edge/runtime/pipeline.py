"""The pipeline: source -> dispatcher -> builder -> sampler -> emit.

``runtime/wiring.py`` builds it, the same for ``run`` (where ``emit`` is the queue
writer), ``run_simulation`` (a sink) and the tests. The source hands every message
that arrives by callback to the dispatcher, which calls the topic's handler and gives
the reading to the builder; at each tick the sampler takes the newest samples of the
state topics from the source (``before_tick``, which returns them), hands them to the
dispatcher, then builds one event from the builder's latest readings and gives it to
``emit``. A live input ticks on the sampler's own loop; an input that keeps its own
time (a bag on its timeline, the simulator in virtual time) ticks from its loop.
An input that can take a mark by hand (the ``ros`` input's ``~/mark`` service) is
given ``Pipeline.mark``: the incident recorder's answer, as a ``MarkReply``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.sampler import Sampler
from phytrace_edge.incident.recorder import IncidentRecorder
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.sources.base import Feed, MarkReply, Source
from phytrace_edge.runtime.supervisor import Beat
from phytrace_edge.udm.types import Built

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Pipeline:
    """The connected stages; ``open`` starts the input, the loops run it."""

    source: Source
    dispatcher: Dispatcher
    builder: UDMBuilder
    sampler: Sampler
    recorder: IncidentRecorder
    emit: Callable[[Built], None]

    @property
    def ticks_itself(self) -> bool:
        """Whether the sampler needs a loop of its own (a live input)."""
        return not self.source.keeps_time

    def open(self) -> None:
        """Open the input: subscriptions, a bag, the simulated robot."""
        self.source.start(
            Feed(
                self.dispatcher.on_message,
                self.sampler.tick,
                self.sampler.period_s,
                self.dispatcher.on_unreadable,
                self.builder.extra_due,
                self.mark,
            )
        )

    def mark(self, reason: str) -> MarkReply:
        """A mark by hand through the input, now: what became of it, in words."""
        marked = self.recorder.mark(reason)
        log.warning("incident marked by hand (%s): %s", marked.outcome, reason)
        ident = marked.incident_id
        if marked.outcome == "opened":
            return MarkReply(True, f"incident {ident} opened: sent once its window ends")
        if marked.outcome == "extended":
            return MarkReply(
                True, f"incident {ident} was already being recorded: its window now ends later"
            )
        if marked.outcome == "rate_limited":
            limit = self.recorder.options.max_per_hour
            return MarkReply(
                False,
                f"rate-limited: nothing recorded, {limit} incident(s) were recorded in the "
                "last hour (INCIDENT_MAX_PER_HOUR)",
            )
        return MarkReply(
            False, "off: nothing recorded, incident recording is off (INCIDENT_RECORDING=false)"
        )

    def ingest(self, stop: threading.Event, beat: Beat) -> None:
        """The input's loop, until ``stop`` or the end of a finite input."""
        self.source.run(stop, beat)

    def tick(self, stop: threading.Event, beat: Beat) -> None:
        """The sample tick's loop for a live input, until ``stop``."""
        self.sampler.run(stop, beat)

    def close(self) -> None:
        """Close the input, then emit the side events it left (a stop loses none) and
        the incident being recorded, cut short."""
        self.source.stop()
        self.sampler.flush_side_events()
        for part in self.recorder.close_now():
            self.emit(part)
