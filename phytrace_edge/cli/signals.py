"""SIGINT and SIGTERM for the commands that run until stopped (``run``, ``drain``,
``import``), and SIGHUP, handled outside the signal handler itself. SIGHUP's default
would end the process without a word; here it re-reads the API key (``run``) or is
ignored with a log line."""

from __future__ import annotations

import logging
import os
import signal
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger("phytrace_edge")


def stop_on_signals(stop: Any) -> None:
    """SIGINT and SIGTERM set ``stop`` (a threading.Event): the sender finishes the
    request on the wire and keeps the rest queued."""
    on_signals(lambda signum: stop.set())


def ignore_hangup() -> None:
    log.warning("SIGHUP: ignored (it only re-reads the API key of a running service)")


def on_signals(
    callback: Callable[[int], None], on_hangup: Callable[[], None] = ignore_hangup
) -> None:
    """Call ``callback(signum)`` for SIGINT and SIGTERM, ``on_hangup()`` for SIGHUP,
    in a thread of its own. A
    Python signal handler runs between two bytecodes of the main thread: setting an
    Event there hangs for good when the main thread was inside that Event's ``wait``
    and held its lock (a SIGTERM that never stopped the service, seen in a test). So
    the handlers do nothing; the interpreter writes each signal's number to a pipe
    (``set_wakeup_fd``), and a thread reads it."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    signal.set_wakeup_fd(write_end)
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, lambda signum, frame: None)

    def watch() -> None:
        while True:
            for signum in os.read(read_end, 64):
                if signum in (signal.SIGINT, signal.SIGTERM):
                    callback(signum)
                elif signum == signal.SIGHUP:
                    on_hangup()

    threading.Thread(target=watch, name="phytrace-signals", daemon=True).start()
