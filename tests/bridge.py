"""The bridge's service in the test's own process, on the simulated robot, sending to a
real stub: its settings, the events it built and its status, and a clean stop."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from phytrace_edge.config import Settings, load_settings
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.runtime import options, wiring
from phytrace_edge.runtime.health import report, thresholds
from phytrace_edge.ship.transport import Transport

WrapTransport = Callable[[Transport], Transport]


def bridge_settings(tmp_path: Path, endpoint: str, **extra: str) -> Settings:
    """A quick robot (50 Hz) and a patient sender, on a queue in ``tmp_path``."""
    env = {
        "PHYCLOUD_ENDPOINT": endpoint,
        "QUEUE_PATH": str(tmp_path / "queue.db"),
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "50",
        "BATCH_SIZE": "25",
        "FLUSH_INTERVAL_S": "0.2",
        "RETRY_MIN_S": "0.05",
        "RETRY_MAX_S": "0.5",
        "HTTP_TIMEOUT_S": "2",
        "SHUTDOWN_GRACE_S": "10",
        **extra,
    }
    return load_settings(env=env).settings


class InProcessBridge:
    """``phytrace-edge run``'s service, wired by the wiring and started (unless
    ``start`` is False: the test looks inside first). ``wrap_transport`` puts a
    test's fault around the real HTTP transport."""

    def __init__(
        self, settings: Settings, wrap_transport: WrapTransport | None = None, start: bool = True
    ) -> None:
        self.settings = settings
        self.built: list[dict[str, Any]] = []  # every event built, in order
        transport = wrap_transport(wiring.http_transport(settings, {})) if wrap_transport else None
        self.service = wiring.build_service(
            settings, {}, transport=transport, on_event=self.built.append
        )
        if start:
            self.service.start()
        self._stopped = False

    def built_ids(self) -> set[str]:
        return {event["event_id"] for event in self.built}

    def status(self) -> dict[str, Any]:
        """What ``status --json`` says now, after a fresh heartbeat."""
        self.service.heartbeat.write(running=True)
        now = self.service.store.now()
        stats = read_stats(options.queue_path(self.settings), now)
        return report(stats, thresholds(self.settings), now)

    def stop(self) -> None:
        """As at SIGTERM; once."""
        if not self._stopped:
            self._stopped = True
            self.service.shutdown(self.settings.shutdown_grace_s)
