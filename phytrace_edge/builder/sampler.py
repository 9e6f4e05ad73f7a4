"""The sample tick: the one loop that turns the builder's latest values into events.

Every input uses it. Live inputs (rclpy, Cyclone DDS, the real-time simulator) let
``Sampler.run`` keep the rate on the monotonic clock, in a thread of its own, so wall
clock jumps and sim time never stretch or squeeze it. Inputs that keep their own time
(a bag replayed on its timeline, the simulator in virtual time) call ``tick`` themselves.

A tick goes one way: the input's take returns the newest samples of the state topics
it reads at the tick, the sampler hands them to the dispatcher (which gives the
builder their readings), then the builder builds. Both are callables given at wiring
(``TickInput``), so the sampler knows nothing of the input or the dispatcher, and the
input never calls back into the dispatcher or the builder.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from phytrace_edge.builder.assemble import DOMAINS
from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.udm.types import Built

Event = dict[str, Any]
Taken = TypeVar("Taken")


@dataclass(frozen=True)
class TickInput(Generic[Taken]):
    """What an input reads at the tick, and where that goes: ``take`` (the input's
    ``before_tick``) takes the newest sample of each state topic and returns them;
    ``dispatch`` (the dispatcher's ``on_taken``) turns them into the builder's
    readings. The type of what is taken is theirs: the sampler only passes it on."""

    take: Callable[[], Taken]
    dispatch: Callable[[Taken], None]


class Sampler:
    """Builds one event per tick and hands it, with its class, to ``emit``.

    An input that reads its state topics at the tick (instead of on every message)
    gives a ``TickInput``: on every tick, first its take, handed to the dispatcher,
    then the build, which sees what was taken.
    """

    def __init__(
        self,
        builder: UDMBuilder,
        emit: Callable[[Built], None],
        rate_hz: float,
        tick_input: TickInput[Any] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        incidents: Callable[[], Sequence[Built]] = tuple,
    ) -> None:
        """``incidents`` gives the incidents whose window ended (the recorder's
        ``take_closed``): emitted at the tick, after the side events."""
        self.builder = builder
        self._incidents = incidents
        self.period_s = 1.0 / rate_hz
        self._emit = emit
        self._input = tick_input
        self._monotonic = monotonic
        self.ticks = 0

    def tick(self, captured_at_s: float | None = None) -> bool:
        """Build and emit the event of this tick; ``captured_at_s`` overrides the wall
        clock (a replay's timeline). The side events (logs, extra topics) go first. An
        event with no domain (nothing fresh was heard)
        is not worth sending: it is not emitted, and the tick returns False."""
        if self._input is not None:
            taken = self._input.take()  # the input only takes: it calls nothing back
            self._input.dispatch(taken)  # the readings reach the builder before it builds
        self.ticks += 1
        self.flush_side_events(captured_at_s)
        built = self.builder.build(captured_at_s)
        if not any(domain in built.event for domain in DOMAINS):
            return False
        self._emit(built)
        return True

    def flush_side_events(self, captured_at_s: float | None = None) -> None:
        """Emit the log records and extra-topic events that came in, and the incidents
        that closed (also at a stop)."""
        for side in self.builder.side_events(captured_at_s):
            self._emit(side)
        for part in self._incidents():
            self._emit(part)

    def run(self, stop: threading.Event, beat: Callable[[], None] = lambda: None) -> None:
        """Tick every period until ``stop``. Ticks are scheduled on the monotonic clock
        without drift; periods missed while the process was stalled are skipped, as
        rcl's timers do, rather than fired in a burst."""
        next_at = self._monotonic() + self.period_s
        while not stop.wait(max(0.0, next_at - self._monotonic())):
            self.tick()
            beat()
            next_at += self.period_s
            now = self._monotonic()
            if next_at <= now:
                next_at = now + self.period_s
