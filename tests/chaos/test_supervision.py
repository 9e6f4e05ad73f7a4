"""A thread of the running bridge dies of an error nobody expected: the supervisor
restarts it, status counts it, and nothing is lost (real queue file, real stub)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from phytrace_edge.config import load_settings
from phytrace_edge.queue.inspect import read_stats
from phytrace_edge.runtime import options, wiring
from phytrace_edge.runtime.health import report, thresholds
from phytrace_edge.ship.responses import Reply
from tests.processes import wait_for


class FailingFirst:
    """The real HTTP transport, except that its first ``failures`` sends raise an error
    the sender does not handle (as a bug in a library would)."""

    def __init__(self, real, failures: int) -> None:
        self.real, self.failures = real, failures

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        if self.failures:
            self.failures -= 1
            raise RuntimeError("injected: the sender thread dies here")
        return self.real.post_events(body, headers)

    def close(self) -> None:
        self.real.close()


def test_a_sender_thread_killed_by_an_exception_is_restarted_and_the_backlog_drains(
    tmp_path: Path, stub
) -> None:
    settings = load_settings(
        env={
            "PHYCLOUD_ENDPOINT": stub.endpoint,
            "QUEUE_PATH": str(tmp_path / "queue.db"),
            "BRIDGE_INPUT": "sim",
            "SAMPLE_RATE_HZ": "20",
            "FLUSH_INTERVAL_S": "0.2",
        }
    ).settings
    built: list[str] = []
    transport = FailingFirst(wiring.http_transport(settings), failures=2)
    service = wiring.build_service(
        settings, {}, transport=transport, on_event=lambda e: built.append(e["event_id"])
    )
    service.start()
    try:
        # the two failing requests may be on the wire at once: one restart, or two
        wait_for(lambda: service.supervisor.restarts["sender"] >= 1, 30, "a sender restart")
        wait_for(lambda: service.sender.stats.events_sent > 20, 30, "sending to resume")
        service.heartbeat.write(running=True)
        document = report(
            read_stats(options.queue_path(settings), service.store.now()),
            thresholds(settings),
            service.store.now(),
        )
        restarts = service.supervisor.restarts["sender"]
        assert document["thread_restarts"]["sender"] == restarts in (1, 2)
        assert document["healthy"], document["problems"]
    finally:
        service.shutdown(settings.shutdown_grace_s)
    assert not service.supervisor.failed.is_set()
    assert service.store_depth_at_stop == 0
    assert set(stub.event_ids()) == set(built)  # the batch in flight was released, not lost
