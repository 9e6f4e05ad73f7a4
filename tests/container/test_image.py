"""The project's image, built and run for real (on the stand-in base, BRIDGE_INPUT=sim,
PhyCloud the stub on the host's loopback): what the container promises in
docs/operations.md, "Run in a container"."""

from __future__ import annotations

import json
import time
from datetime import datetime

import pytest

from tests.container.conftest import Docker, docker
from tests.processes import wait_for

pytestmark = pytest.mark.timeout(900)  # the first test builds the image

FAST_HEALTH = ("--health-interval", "2s", "--health-start-period", "2s", "--health-retries", "2")


def bridge_env(endpoint: str, **extra: str) -> dict[str, str]:
    return {
        "PHYCLOUD_ENDPOINT": endpoint,
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "10",
        "FLUSH_INTERVAL_S": "0.5",
        "RETRY_MAX_S": "1",
        "HEALTH_EVENT_INTERVAL_S": "0",
        **extra,
    }


def seconds(stamp: str) -> float:
    return datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()


def test_a_running_bridge_is_unprivileged_private_healthy_and_stops_cleanly(
    containers: Docker, stub
) -> None:
    queue = containers.volume("queue")
    bridge = containers.run(
        "bridge",
        "-v",
        f"{queue}:/var/lib/phytrace-edge",
        *FAST_HEALTH,
        env=bridge_env(stub.endpoint),
    )
    containers.wait_health(bridge, "healthy")
    assert containers.exec(bridge, "id", "-u") == "10001"
    listing = containers.exec(bridge, "find", "/var/lib/phytrace-edge", "-printf", "%m %y %p\\n")
    modes = [line.split(" ", 2) for line in listing.splitlines()]
    assert any(path.endswith("/queue.db") for _, _, path in modes)
    for mode, kind, path in modes:  # the events are private: files 0600, folders 0700
        assert mode == ("600" if kind == "f" else "700"), (mode, kind, path)
    assert "not on a mounted volume" not in containers.logs(bridge)
    assert "anonymous volume" not in containers.logs(bridge)
    wait_for(lambda: stub.stats()["unique"] > 20, 60, "events at the stub")
    started = time.monotonic()
    docker("stop", bridge, timeout=60)
    assert containers.state(bridge)["ExitCode"] == 0
    assert time.monotonic() - started < 15  # well within docker stop's 10 s + flush
    assert "stopped; 0 event(s) left in the queue" in containers.logs(bridge)


def test_a_refused_key_turns_the_container_unhealthy(containers: Docker, stub_factory) -> None:
    stub = stub_factory("--api-key", "the-right-key")
    bridge = containers.run(
        "refused",
        "-v",
        f"{containers.volume('queue')}:/var/lib/phytrace-edge",
        *FAST_HEALTH,
        env=bridge_env(stub.endpoint, PHYCLOUD_API_KEY="a-wrong-key"),
    )
    containers.wait_health(bridge, "unhealthy")
    status = containers.exec(bridge, "sh", "-c", "phytrace-edge status || true")
    assert "PhyCloud refuses the API key (HTTP 401)" in status
    assert "a-wrong-key" not in status + containers.logs(bridge)


def test_without_a_volume_the_bridge_warns_loudly(containers: Docker, stub) -> None:
    bridge = containers.run("no-volume", env=bridge_env(stub.endpoint))
    wait_for(lambda: "anonymous volume" in containers.logs(bridge), 60, "the warning")
    assert "!!! the queue /var/lib/phytrace-edge/queue.db is on an anonymous volume" in (
        containers.logs(bridge)
    )


def test_a_killed_containers_backlog_goes_with_the_next_one_without_a_lease_wait(
    containers: Docker, stub_factory
) -> None:
    stub = stub_factory()
    stub.kill()  # PhyCloud is down for the first one
    endpoint = stub.endpoint
    queue = containers.volume("queue")
    first = containers.run(
        "first", "-v", f"{queue}:/var/lib/phytrace-edge", env=bridge_env(endpoint)
    )

    def depth() -> int:
        document = containers.exec(first, "sh", "-c", "phytrace-edge status --json || true")
        return int(json.loads(document)["queue"]["depth"]) if document else 0

    wait_for(lambda: depth() > 50, 60, "a backlog in the first container")
    docker("kill", first)
    killed_at = time.time()
    docker("rm", first)
    containers.containers.remove(first)
    status = docker(
        "run",
        "--rm",
        "-v",
        f"{queue}:/var/lib/phytrace-edge",
        containers.image,
        "sh",
        "-c",
        "phytrace-edge status --json || true",
    ).stdout
    queued = int(json.loads(status)["queue"]["depth"])
    assert queued > 50

    stub.start()  # back, on the same port
    second_started = time.monotonic()
    containers.run("second", "-v", f"{queue}:/var/lib/phytrace-edge", env=bridge_env(endpoint))

    def backlog_delivered() -> bool:
        old = [e for e in stub.events() if seconds(e["captured_at"]) <= killed_at]
        return len(old) >= queued

    wait_for(backlog_delivered, 60, "the killed container's backlog at PhyCloud")
    # a lease runs at least 60 s: the dead container's claims were taken back at once
    assert time.monotonic() - second_started < 45
    old = [e for e in stub.events() if seconds(e["captured_at"]) <= killed_at]
    assert len(old) == queued and stub.stats()["duplicates"] == 0
