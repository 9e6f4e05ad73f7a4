"""The sender against the real stub process over loopback HTTP."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import httpx
import orjson
import pytest

from phytrace_edge import run_simulation
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport
from phytrace_edge.units import MIB
from tests.queue_events import put_events


@pytest.fixture(scope="module")
def sim_events() -> list[dict]:
    """The simulated robot's periodic events (the tests change their domains)."""
    events: list[dict] = []
    run_simulation(600, sink=events.append, seed=5)
    return [event for event in events if event["event_type"] == "telemetry.periodic"]


@pytest.fixture
def queue(tmp_path: Path):
    with QueueStore.open(tmp_path / "queue.db", limits=QueueLimits(max_bytes=256 * MIB)) as store:
        yield store


def make_sender(queue, stub, key: str = "", stop=None, sleep=None, **policy) -> Sender:
    transport = HttpTransport(stub.endpoint, Secret(key), timeout_s=10)
    policy.setdefault("batch_size", 50)
    return Sender(queue, transport, SendPolicy(**policy), stop=stop, sleep=sleep)


@pytest.mark.parametrize("encoding", ["gzip", "zstd", "none"])
def test_every_event_arrives_exactly_once(queue, stub, sim_events, encoding: str) -> None:
    put_events(queue, sim_events)
    sender = make_sender(queue, stub, http_compression=encoding)
    assert sender.drain(deadline=time.monotonic() + 60) is True
    assert sorted(stub.event_ids()) == sorted(e["event_id"] for e in sim_events)
    stats = stub.stats()
    assert stats["unique"] == len(sim_events) and stats["duplicates"] == 0
    assert stats["by_source"] == {"delivery-robot-001": len(sim_events)}
    stored = httpx.get(f"{stub.endpoint}/events", params={"limit": 1}).json()["events"][0]
    assert stored == sim_events[0]


def test_api_key_is_checked_and_never_dropped(queue, stub_factory, sim_events) -> None:
    stub = stub_factory("--api-key", "phk_test_secret")
    put_events(queue, sim_events[:30])
    waits: list[float] = []
    stop = threading.Event()

    def give_up_after_three(seconds: float) -> None:
        waits.append(seconds)
        if len(waits) == 3:
            stop.set()

    wrong = make_sender(
        queue, stub, key="phk_wrong", stop=stop, sleep=give_up_after_three, retry_max_s=7
    )
    assert wrong.drain() is False
    assert waits == [7, 7, 7] and wrong.stats.auth_failures == 3
    assert queue.stats().depth == 30 and stub.stats()["unique"] == 0
    right = make_sender(queue, stub, key="phk_test_secret")
    assert right.drain(deadline=time.monotonic() + 30) is True
    assert stub.stats()["unique"] == 30


def test_503_with_retry_after_is_honoured_then_recovers(queue, stub, sim_events) -> None:
    stub.set_faults(fixed_status=503, retry_after="2")
    put_events(queue, sim_events[:20])
    waits: list[float] = []

    def wait_and_recover(seconds: float) -> None:
        waits.append(seconds)
        if len(waits) == 3:
            stub.set_faults(fixed_status=None, retry_after=None)

    sender = make_sender(queue, stub, sleep=wait_and_recover)
    assert sender.drain(deadline=time.monotonic() + 30) is True
    assert len(waits) == 3 and all(2 <= w <= 2.4 for w in waits)
    assert stub.stats()["unique"] == 20 and queue.stats().drops == {}


def test_one_poisoned_event_in_a_batch_of_500(queue, stub, sim_events) -> None:
    events = [
        {**sim_events[i % len(sim_events)], "event_id": f"{i:08d}-0000-7000-8000-000000000000"}
        for i in range(500)
    ]
    events[317] = {**events[317], "power": {"battery": {"state_of_charge_pct": 250.0}}}
    put_events(queue, events)
    sender = make_sender(queue, stub, batch_size=500)
    assert sender.drain(deadline=time.monotonic() + 60) is True
    assert stub.stats()["unique"] == 499
    (letter,) = queue.dead_letters.list()
    assert letter.event_id == events[317]["event_id"] and letter.status_code == 400
    assert "/power/battery/state_of_charge_pct" in (letter.response or "")


def test_partial_rejections_in_a_200_are_dead_lettered(queue, stub_factory, sim_events) -> None:
    stub = stub_factory("--partial-rejects")
    bad = {**sim_events[1], "source_type": "boat"}
    put_events(queue, [sim_events[0], bad, sim_events[2]])
    assert make_sender(queue, stub).drain(deadline=time.monotonic() + 30) is True
    assert stub.stats()["unique"] == 2
    (letter,) = queue.dead_letters.list()
    assert letter.event_id == bad["event_id"] and "source_type" in letter.reason


def test_dropped_connections_lose_nothing_and_duplicates_are_counted(
    queue, stub_factory, sim_events
) -> None:
    stub = stub_factory("--drop-rate", "0.4", "--seed", "3")
    events = sim_events[:250]
    put_events(queue, events)
    sender = make_sender(queue, stub, batch_size=20, retry_min_s=0.01, retry_max_s=0.05)
    assert sender.drain(deadline=time.monotonic() + 60) is True
    stats = stub.stats()
    assert stats["unique"] == len(events) == 250
    assert stats["duplicates"] > 0  # stored, then the answer was lost, then resent
    assert sender.stats.retries > 0 and "RemoteProtocolError" in (sender.stats.last_error or "")


def test_stub_record_survives_a_restart(stub, sim_events) -> None:
    body = orjson.dumps({"events": sim_events[:5]})
    assert httpx.post(f"{stub.endpoint}/events", content=body).json()["accepted"] == 5
    stub.kill()
    stub.start()
    assert stub.stats()["unique"] == 5
    again = httpx.post(f"{stub.endpoint}/events", content=body).json()
    assert (again["accepted"], again["duplicates"]) == (0, 5)


def test_fault_settings_are_validated(stub) -> None:
    response = httpx.put(f"{stub.endpoint}/faults", json={"error_rate": 2})
    assert response.status_code == 400 and "error_rate" in response.json()["error"]
    response = httpx.put(f"{stub.endpoint}/faults", json={"nonsense": 1})
    assert response.status_code == 400
    assert httpx.get(f"{stub.endpoint}/faults").json()["error_rate"] == 0.0
