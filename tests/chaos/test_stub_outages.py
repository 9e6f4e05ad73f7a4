"""Chaos: PhyCloud dies and comes back while a robot keeps producing.

The bridge runs in this process (simulated robot at a high sample rate, real queue
file, real HTTP); the stub is a separate process killed with SIGKILL and restarted on
the same port and database. At the end every event the bridge built must be in the
stub exactly once as a unique event_id.
"""

from __future__ import annotations

import random
import time

from phytrace_edge.runtime.options import send_policy
from phytrace_edge.runtime.wiring import http_transport, open_queue
from phytrace_edge.ship.sender import Sender
from tests.processes import wait_for

KILLS = 5


def more_than(items: list, count: int):
    """A condition: ``count`` more items than now."""
    target = len(items) + count
    return lambda: len(items) > target


def drain_rest(settings) -> None:
    """After the bridge stopped: send what is still queued (as `drain` would)."""
    with open_queue(settings) as store:
        sender = Sender(store, http_transport(settings, {}), send_policy(settings))
        assert sender.drain(deadline=time.monotonic() + 60), "the queue did not drain"


def test_stub_killed_five_times_loses_nothing(stub, bridge_in_process) -> None:
    rng = random.Random(42)
    bridge = bridge_in_process(stub.endpoint)
    built = bridge.built
    try:
        for kill in range(KILLS):
            wait_for(more_than(built, rng.randint(10, 40)), 30, "the robot to build more events")
            stub.kill()
            # down while events pile up
            wait_for(more_than(built, rng.randint(10, 60)), 30, f"events during outage {kill + 1}")
            stub.start()
        wait_for(more_than(built, 50), 30, "events after the last restart")
    finally:
        bridge.stop()
    drain_rest(bridge.settings)

    received = stub.event_ids()
    stats = stub.stats()
    print(
        f"\nbuilt {len(built)} events, stub received {stats['received']} "
        f"({stats['duplicates']} duplicates) over {KILLS} SIGKILLs"
    )
    assert len(set(received)) == len(received)  # the stub stores each event once
    assert set(received) == bridge.built_ids(), (
        f"lost: {len(bridge.built_ids() - set(received))}, "
        f"unexpected: {len(set(received) - bridge.built_ids())}"
    )
    with open_queue(bridge.settings) as store:
        queue = store.stats()
    assert queue.depth == 0 and queue.drops == {} and queue.dead_letters == 0


def test_503_with_retry_after_for_a_while_then_recovery(stub, bridge_in_process) -> None:
    stub.set_faults(fixed_status=503, retry_after="1")
    bridge = bridge_in_process(stub.endpoint, SAMPLE_RATE_HZ="20")
    sender = bridge.service.sender
    try:
        wait_for(lambda: sender.stats.retries >= 2, 30, "retries while PhyCloud is down")
        assert stub.stats()["unique"] == 0
        assert sender.stats.last_status == 503
        stub.set_faults(fixed_status=None, retry_after=None)
        wait_for(lambda: sender.stats.last_success_at, 30, "the first success")
    finally:
        bridge.stop()
    drain_rest(bridge.settings)
    assert set(stub.event_ids()) == bridge.built_ids()


def test_401_for_a_while_drops_nothing(stub, bridge_in_process) -> None:
    stub.set_faults(fixed_status=401)
    bridge = bridge_in_process(stub.endpoint, SAMPLE_RATE_HZ="20", RETRY_MAX_S="0.3")
    service = bridge.service
    try:
        wait_for(lambda: service.sender.stats.auth_failures >= 3, 30, "repeated 401s")
        assert service.store.stats().drops == {}
        stub.set_faults(fixed_status=None)  # the key is accepted again
        wait_for(lambda: service.sender.stats.last_success_at, 30, "the first success")
    finally:
        bridge.stop()
    drain_rest(bridge.settings)
    assert set(stub.event_ids()) == bridge.built_ids()
