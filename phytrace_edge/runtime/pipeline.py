"""The pipeline: source -> dispatcher -> builder -> sampler -> emit.

``runtime/wiring.py`` builds it, the same for ``run`` (where ``emit`` is the queue
writer), ``run_simulation`` (a sink) and the tests. The source hands every message
that arrives by callback to the dispatcher, which calls the topic's handler and gives
the reading to the builder; at each tick the sampler takes the newest samples of the
state topics from the source (``before_tick``, which returns them), hands them to the
dispatcher, then builds one event from the builder's latest readings and gives it to
``emit``. A live input ticks on the sampler's own loop; an input that keeps its own
time (a bag on its timeline, the simulator in virtual time) ticks from its loop.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.sampler import Sampler
from phytrace_edge.incident.recorder import IncidentRecorder
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.sources.base import Feed, Source
from phytrace_edge.runtime.supervisor import Beat
from phytrace_edge.udm.types import Built


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
            )
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
