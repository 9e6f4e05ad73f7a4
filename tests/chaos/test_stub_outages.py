"""Chaos: PhyCloud dies and comes back while a robot keeps producing.

The bridge runs in this process (simulated robot at a high sample rate, real queue
file, real HTTP); the stub is a separate process killed with SIGKILL and restarted on
the same port and database. At the end every event the bridge built must be in the
stub exactly once as a unique event_id.
"""

from __future__ import annotations

import random
import time
from pathlib import Path

from phytrace_edge.config import load_settings
from phytrace_edge.runtime.wiring import build_service, http_transport, open_queue, send_policy
from phytrace_edge.ship.sender import Sender
from tests.processes import wait_for

KILLS = 5


def bridge_settings(tmp_path: Path, endpoint: str, **extra: str):
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


def more_than(items: list, count: int):
    """A condition: ``count`` more items than now."""
    target = len(items) + count
    return lambda: len(items) > target


def drain_rest(settings) -> None:
    """After the bridge stopped: send what is still queued (as `drain` would)."""
    with open_queue(settings) as store:
        sender = Sender(store, http_transport(settings), send_policy(settings))
        assert sender.drain(deadline=time.monotonic() + 60), "the queue did not drain"


def test_stub_killed_five_times_loses_nothing(tmp_path: Path, stub) -> None:
    rng = random.Random(42)
    built: list[str] = []
    settings = bridge_settings(tmp_path, stub.endpoint)
    service = build_service(settings, {}, on_event=lambda event: built.append(event["event_id"]))
    service.start()
    try:
        for kill in range(KILLS):
            wait_for(more_than(built, rng.randint(10, 40)), 30, "the robot to build more events")
            stub.kill()
            # down while events pile up
            wait_for(more_than(built, rng.randint(10, 60)), 30, f"events during outage {kill + 1}")
            stub.start()
        wait_for(more_than(built, 50), 30, "events after the last restart")
    finally:
        service.shutdown(settings.shutdown_grace_s)
    drain_rest(settings)

    received = stub.event_ids()
    stats = stub.stats()
    print(
        f"\nbuilt {len(built)} events, stub received {stats['received']} "
        f"({stats['duplicates']} duplicates) over {KILLS} SIGKILLs"
    )
    assert len(set(received)) == len(received)  # the stub stores each event once
    assert set(received) == set(built), (
        f"lost: {len(set(built) - set(received))}, unexpected: {len(set(received) - set(built))}"
    )
    with open_queue(settings) as store:
        queue = store.stats()
    assert queue.depth == 0 and queue.drops == {} and queue.dead_letters == 0


def test_503_with_retry_after_for_a_while_then_recovery(tmp_path: Path, stub) -> None:
    built: list[str] = []
    settings = bridge_settings(tmp_path, stub.endpoint, SAMPLE_RATE_HZ="20")
    service = build_service(settings, {}, on_event=lambda event: built.append(event["event_id"]))
    stub.set_faults(fixed_status=503, retry_after="1")
    service.start()
    try:
        wait_for(lambda: service.sender.stats.retries >= 2, 30, "retries while PhyCloud is down")
        assert stub.stats()["unique"] == 0
        assert service.sender.stats.last_status == 503
        stub.set_faults(fixed_status=None, retry_after=None)
        wait_for(lambda: service.sender.stats.last_success_at, 30, "the first success")
    finally:
        service.shutdown(settings.shutdown_grace_s)
    drain_rest(settings)
    assert set(stub.event_ids()) == set(built)


def test_401_for_a_while_drops_nothing(tmp_path: Path, stub) -> None:
    built: list[str] = []
    settings = bridge_settings(tmp_path, stub.endpoint, SAMPLE_RATE_HZ="20", RETRY_MAX_S="0.3")
    service = build_service(settings, {}, on_event=lambda event: built.append(event["event_id"]))
    stub.set_faults(fixed_status=401)
    service.start()
    try:
        wait_for(lambda: service.sender.stats.auth_failures >= 3, 30, "repeated 401s")
        assert service.store.stats().drops == {}
        stub.set_faults(fixed_status=None)  # the key is accepted again
        wait_for(lambda: service.sender.stats.last_success_at, 30, "the first success")
    finally:
        service.shutdown(settings.shutdown_grace_s)
    drain_rest(settings)
    assert set(stub.event_ids()) == set(built)
