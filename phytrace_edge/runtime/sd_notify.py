"""systemd's notify protocol (``Type=notify``, ``WatchdogSec=``), in a few lines of stdlib.

systemd passes ``$NOTIFY_SOCKET`` (a path, or ``@name`` for the abstract namespace) and,
with a watchdog, ``$WATCHDOG_USEC``. The service says READY=1 once it is up,
WATCHDOG=1 more often than the watchdog interval while it is healthy, STATUS= for
``systemctl status``, and STOPPING=1 when it begins to stop. Outside systemd (no
``$NOTIFY_SOCKET``) every call does nothing.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping

from phytrace_edge.ship.stats import SendStats


class SystemdNotifier:
    def __init__(self, env: Mapping[str, str]) -> None:
        address = env.get("NOTIFY_SOCKET", "")
        self._address = "\0" + address[1:] if address.startswith("@") else address
        watchdog_usec = env.get("WATCHDOG_USEC", "")
        watchdog_pid = env.get("WATCHDOG_PID", "")
        mine = not watchdog_pid or watchdog_pid == str(os.getpid())
        self.watchdog_s = int(watchdog_usec) / 1e6 if watchdog_usec.isdigit() and mine else None

    def notify(self, **fields: str) -> None:
        """Send ``READY=1`` and the like: ``notify(READY="1", STATUS="...")``."""
        if not self._address:
            return
        message = "\n".join(f"{key}={value}" for key, value in fields.items()).encode()
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
            sock.connect(self._address)
            sock.sendall(message)

    def ready(self, status: str) -> None:
        self.notify(READY="1", STATUS=status)

    def watchdog(self, status: str) -> None:
        self.notify(WATCHDOG="1", STATUS=status)

    def stopping(self) -> None:
        self.notify(STOPPING="1", STATUS="stopping: flushing the queue")


def status_line(depth: int, stats: SendStats, now: float) -> str:
    """One line for `systemctl status`: the queue, what was sent, the last outcome."""
    last = "never" if stats.last_success_at is None else f"{now - stats.last_success_at:.0f} s ago"
    line = f"{depth} queued, {stats.events_sent} sent, last success {last}"
    return line + (f", last error {stats.last_error}" if stats.last_error else "")
