"""Where built events leave the pipeline: checked against the UDM schema (a violation
is logged and the event still kept), counted, shown to an observer (the tests) and
handed to the queue writer. The sampler and the health events both emit here."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from phytrace_edge.builder.builder import Built
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.udm.schema import check_event

log = logging.getLogger(__name__)


class Outlet:
    """``emit`` hands an event to the writer; an input that keeps its own time (a bag)
    waits for the disk instead of outrunning it (``wait_for_disk``)."""

    def __init__(
        self,
        writer: QueueWriter,
        wait_for_disk: bool,
        on_event: Callable[[dict[str, Any]], None] | None = None,
    ) -> None:
        self.writer = writer
        self.wait_for_disk = wait_for_disk
        self.events_built = 0
        self._on_event = on_event
        self._lock = threading.Lock()

    def emit(self, built: Built) -> None:
        with self._lock:
            self.events_built += 1
        check_event(built.event, log)
        if self._on_event is not None:
            self._on_event(built.event)
        self.writer.put(built, wait=self.wait_for_disk)
