"""``run_simulation``: the simulated delivery robot through ingest and build, end to end.

The robot and the bridge's node share one mock ROS context, and the bridge hears the
robot through the ``ros`` input's own code (take-at-tick included). By default time
is virtual, so 100 robot cycles (10 s of robot time at 10 Hz) run in a fraction of a
second; ``realtime=True`` runs at wall-clock pace. Events go through the pipeline
``runtime/wiring.py`` builds for ``phytrace-edge run``, then to ``sink``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from phytrace_edge.config import Settings
from phytrace_edge.runtime import wiring
from phytrace_edge.udm.schema import check_event
from phytrace_edge.udm.types import Built, UdmEvent

log = logging.getLogger(__name__)

Event = UdmEvent


def run_simulation(
    num_ticks: int = 100,
    *,
    settings: Settings | None = None,
    sink: Callable[[Event], None] | None = None,
    seed: int = 0,
    realtime: bool = False,
) -> dict[str, Any]:
    """Run the simulated robot for ``num_ticks`` robot cycles (10 Hz) through the bridge.

    Every built event is validated against the UDM schema and handed to ``sink``
    (default: kept in memory and discarded at the end). Returns
    ``{"events_sent", "events_failed", "topics_seen", "duration_s"}``: events the sink
    accepted, events that failed validation or that the sink refused, the topics the
    bridge received messages on, and the wall-clock duration of the run.
    """
    if num_ticks < 0:
        raise ValueError("num_ticks must be >= 0")
    collected: list[Event] = []
    sink = sink or collected.append
    counts = {"sent": 0, "failed": 0}

    def emit(built: Built) -> None:
        event = built.event
        if not check_event(event, log):
            counts["failed"] += 1
            return
        try:
            sink(event)
        except Exception:
            log.exception("sink refused event %s", event["event_id"])
            counts["failed"] += 1
        else:
            counts["sent"] += 1

    pipeline = wiring.simulation_pipeline(
        settings, emit, seed=seed, realtime=realtime, max_ticks=num_ticks
    )
    started = time.monotonic()
    stop = threading.Event()
    ticker = threading.Thread(target=pipeline.tick, args=(stop, lambda: None), name="sampler")
    try:
        pipeline.open()
        if pipeline.ticks_itself:
            ticker.start()
        pipeline.ingest(stop, lambda: None)
    finally:
        stop.set()
        if ticker.is_alive():
            ticker.join()
        pipeline.source.stop()
    return {
        "events_sent": counts["sent"],
        "events_failed": counts["failed"],
        "topics_seen": pipeline.builder.topics_seen(),
        "duration_s": round(time.monotonic() - started, 3),
    }
