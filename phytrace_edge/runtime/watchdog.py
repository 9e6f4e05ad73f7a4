"""The service's main loop under systemd: READY once it runs, the watchdog fed only
while every stage makes progress, STOPPING and a clean stop when asked.

A stage that makes no progress for its ``stall_after_s`` (one rule: ``health.stalled``)
starves the watchdog, and systemd restarts the service; ``status`` names the stage.
"""

from __future__ import annotations

import logging
import threading
import time

from phytrace_edge.runtime.sd_notify import SystemdNotifier
from phytrace_edge.runtime.service import BridgeService

log = logging.getLogger(__name__)

WATCHDOG_IDLE_S = 5.0  # how often progress is checked without a systemd watchdog
POLL_S = 0.2


def serve(service: BridgeService, notifier: SystemdNotifier, stop: threading.Event) -> None:
    """Start ``service``, run it until ``stop`` is set, an input ends or a stage cannot
    be kept alive, then shut it down."""
    log.info("%s", service.summary())
    service.start()
    notifier.ready(service.status_line())
    interval = notifier.watchdog_s / 2 if notifier.watchdog_s else WATCHDOG_IDLE_S
    next_check = time.monotonic() + interval
    while not stop.wait(POLL_S):
        if service.finished.is_set() or service.supervisor.failed.is_set():
            break
        if time.monotonic() < next_check:
            continue
        next_check = time.monotonic() + interval
        if service.healthy():
            notifier.watchdog(service.status_line())
        else:
            log.error("a stage of the service makes no progress; letting the watchdog act")
    notifier.stopping()
    service.shutdown(service.options.shutdown_grace_s)
