"""A thread of the running bridge dies of an error nobody expected: the supervisor
restarts it, status counts it, and nothing is lost (real queue file, real stub)."""

from __future__ import annotations

from collections.abc import Mapping

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
    stub, bridge_in_process
) -> None:
    bridge = bridge_in_process(
        stub.endpoint,
        wrap_transport=lambda real: FailingFirst(real, failures=2),
        SAMPLE_RATE_HZ="20",
    )
    service = bridge.service
    # the two failing requests may be on the wire at once: one restart, or two
    wait_for(lambda: service.supervisor.restarts["sender"] >= 1, 30, "a sender restart")
    wait_for(lambda: service.sender.stats.events_sent > 20, 30, "sending to resume")
    document = bridge.status()
    restarts = service.supervisor.restarts["sender"]
    assert document["thread_restarts"]["sender"] == restarts in (1, 2)
    assert document["healthy"], document["problems"]
    bridge.stop()
    assert not service.supervisor.failed.is_set()
    assert service.store_depth_at_stop == 0
    assert set(stub.event_ids()) == bridge.built_ids()  # the batch in flight: released, not lost
