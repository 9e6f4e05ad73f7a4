"""Incidents from a replayed rosbag, end to end: ``phytrace-edge run --input bag:`` to a
real stub. The bag (tests/incident_bag.py): /odom at 50 Hz and /imu/data at 100 Hz for
120 s, a /diagnostics ERROR from 60 s. The stub must receive one incident whose /odom
samples cover [30 s, 70 s] of bag time at full rate with the values published, at
any REPLAY_RATE, and the same incident whole after an outage, a restart and thinning.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from phytrace_edge.config import Settings
from phytrace_edge.incident.parts import incident_id
from phytrace_edge.incident.triggers import Trigger
from phytrace_edge.udm.event import parse_timestamp
from phytrace_edge.udm.types import UdmIdentity
from tests.incident_bag import BAG_START_S, ODOM_HZ, speed_of, write_incident_bag
from tests.processes import BridgeProcess, StubProcess, python_env, run_cli, status_json, wait_for

pytest.importorskip("rosbags", reason="bag replay needs rosbags (pip install .[bag])")


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("incident") / "bump"
    counts = write_incident_bag(path)
    assert counts == {"/odom": 6000, "/imu/data": 12000, "/diagnostics": 120}
    return path


def replay(bag: Path, queue: Path, endpoint: str, rate: str, **env: str) -> str:
    """``run --input bag:`` to its end; its stdout."""
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "run", "--input", f"bag:{bag}", "--rate", rate],
        capture_output=True,
        text=True,
        timeout=600,
        env=python_env(
            PHYCLOUD_ENDPOINT=endpoint,
            QUEUE_PATH=str(queue),
            FLUSH_INTERVAL_S="0.2",
            RETRY_MIN_S="0.05",
            RETRY_MAX_S="0.5",
            **env,
        ),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return result.stdout


def incidents(events: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The incident parts received, by incident id, in part order."""
    found: dict[str, list[dict[str, Any]]] = {}
    for event in events:
        if event["event_type"] == "incident":
            found.setdefault(event["incident"]["id"], []).append(event)
    return {i: sorted(parts, key=lambda e: e["incident"]["part"]) for i, parts in found.items()}


def joined(parts: list[dict[str, Any]], topic: str) -> list[dict[str, Any]]:
    return [sample for part in parts for sample in part["incident"]["samples"].get(topic, [])]


def bag_seconds(timestamp: str) -> float:
    return parse_timestamp(timestamp) - BAG_START_S


def check_the_incident(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One whole incident around the ERROR at 60 s, every /odom and /imu/data message of
    [30 s, 70 s] in it exactly as published; its parts."""
    (parts,) = incidents(events).values()
    assert [p["incident"]["part"] for p in parts] == list(
        range(1, parts[0]["incident"]["parts"] + 1)
    )
    incident = parts[0]["incident"]
    assert incident["trigger"]["kind"] == "diagnostics"
    assert incident["trigger"]["message"] == "bumper: contact: hit an obstacle"
    assert bag_seconds(incident["trigger"]["at"]) == 60.0
    assert bag_seconds(incident["window"]["start"]) == 30.0
    assert bag_seconds(incident["window"]["end"]) == 70.0
    odom = joined(parts, "/odom")
    times = [bag_seconds(s["t"]) for s in odom]
    assert times == sorted(times) and times[0] == pytest.approx(30.0, abs=1e-6)
    assert times[-1] == pytest.approx(70.0, abs=1e-6) and len(odom) / 40 >= 45
    # message n of /odom is at n/50 s: its speed says which it was
    for sample, at in zip(odom, times, strict=True):
        n = round(at * ODOM_HZ)
        assert sample["linear_velocity"]["x_mps"] == speed_of(n), (at, sample)
    imu = joined(parts, "/imu/data")
    assert len(imu) == 4001  # [30 s, 70 s] at 100 Hz, both ends
    for k in (0, 123, 3999):  # message n turns at n % 90 degrees a second
        assert imu[k]["imu"]["angular_velocity_dps"]["z"] == pytest.approx((3000 + k) % 90)
    return parts


def expected_incident_id() -> str:
    """The id the ERROR at 60 s of bag time gives (derived: the same at any rate)."""
    trigger = Trigger("diagnostics", "", 60.0, BAG_START_S + 60.0, "/diagnostics", "error")
    return incident_id(UdmIdentity(source_id=Settings().source_id, source_type="x"), trigger)


@pytest.mark.timeout(400)  # at REPLAY_RATE 1, the bag's 120 s
@pytest.mark.parametrize("rate", ["0", pytest.param("1", marks=pytest.mark.paced)])
def test_a_replay_gives_one_incident_at_full_rate_at_any_replay_rate(
    bag: Path, tmp_path: Path, stub: StubProcess, rate: str
) -> None:
    out = replay(bag, tmp_path / "q.db", stub.endpoint, rate)
    assert out.startswith(f"replayed {bag}: ")
    events = stub.events()
    parts = check_the_incident(events)
    assert parts[0]["incident"]["id"] == expected_incident_id()  # the same at any rate
    periodic = [
        bag_seconds(e["captured_at"]) for e in events if e["event_type"] == "telemetry.periodic"
    ]
    outside = [t for t in periodic if t < 29 or t > 71]
    # outside the window, the events keep to SAMPLE_RATE_HZ (5): 29 s before, 49 s after
    assert len([t for t in outside if t < 29]) == pytest.approx(29 * 5, abs=2)
    assert len([t for t in outside if t > 71]) == pytest.approx(49 * 5, abs=2)


@pytest.mark.paced
@pytest.mark.timeout(400)
def test_the_incident_arrives_whole_after_an_outage_a_restart_and_thinning(
    bag: Path, tmp_path: Path
) -> None:
    """PhyCloud down for the whole replay, the bridge killed in the middle (after the
    incident was queued) and started again, a queue small enough to thin: once PhyCloud
    is back, the incident arrives whole, once."""
    stub = StubProcess(tmp_path / "stub.db")  # its port is chosen; nothing listens yet
    queue = tmp_path / "q.db"
    settings = {
        "PHYCLOUD_ENDPOINT": stub.endpoint,
        "QUEUE_PATH": str(queue),
        "QUEUE_MAX_EVENTS": "800",  # two replays: 1,200 periodic events, and the incident
        "QUEUE_ON_FULL": "thin",
        "REPLAY_RATE": "4",  # 30 s: rows older than the live end, which thinning spares
        "BRIDGE_INPUT": f"bag:{bag}",
        "RETRY_MIN_S": "0.05",
        "RETRY_MAX_S": "0.5",
    }
    bridge = BridgeProcess(tmp_path / "bridge.log", **settings).start()
    try:
        run_the_outage(bridge, stub, bag, queue)
    finally:
        bridge.stop()
        stub.stop()


def run_the_outage(bridge: BridgeProcess, stub: StubProcess, bag: Path, queue: Path) -> None:
    def recorded() -> bool:
        _, status = status_json(QUEUE_PATH=str(queue))
        return status.get("incidents", {}).get("parts", 0) >= 1

    wait_for(recorded, 120, "the incident queued")
    bridge.signal(signal.SIGKILL)  # a power cut, in the middle of the replay
    bridge.wait(10)
    out = replay(bag, queue, stub.endpoint, "4", QUEUE_MAX_EVENTS="800", QUEUE_ON_FULL="thin")
    assert "still queued" in out  # PhyCloud is down: everything waits
    _, before = status_json(QUEUE_PATH=str(queue))
    assert before["resolution"], before["queue"]  # the periodic history was thinned
    assert before["drops"].get("thinned", 0) > 0, before["drops"]
    stub.start()
    drained = run_cli(
        "drain", "--timeout", "120", QUEUE_PATH=str(queue), PHYCLOUD_ENDPOINT=stub.endpoint
    )
    assert drained.returncode == 0, drained.stderr
    events = stub.events()
    parts = check_the_incident(events)
    assert Counter(e["event_id"] for e in events if e["event_type"] == "incident") == {
        p["event_id"]: 1 for p in parts
    }


@pytest.mark.paced
@pytest.mark.timeout(400)
def test_an_incident_in_the_third_hour_of_an_outage_is_sent_first(tmp_path: Path) -> None:
    """Three hours of a robot (bag time, replayed in about a minute at REPLAY_RATE 180)
    with PhyCloud down throughout and a queue small enough that the oldest hours are
    thinned, a bumper ERROR at 2 h 30 min. When PhyCloud comes back, the incident's
    parts are the first events it receives, before the first hour's backlog, and the
    incident is whole: every /odom message of its window, as published."""
    bag = tmp_path / "three-hours"
    hours, error_at_s, odom_hz = 3, 9000, 2
    counts = write_incident_bag(
        bag, hours * 3600, error_at_s, odom_hz=odom_hz, imu_hz=1, diagnostics_every_s=10
    )
    assert counts == {"/odom": 21600, "/imu/data": 10800, "/diagnostics": 1080}
    stub = StubProcess(tmp_path / "stub.db")  # its port is chosen; nothing listens yet
    queue = tmp_path / "q.db"
    out = replay(
        bag,
        queue,
        stub.endpoint,
        "180",
        SAMPLE_RATE_HZ="1",
        QUEUE_MAX_EVENTS="2000",  # of 10,800 periodic events
        QUEUE_ON_FULL="thin",
    )
    assert "still queued" in out  # PhyCloud is down: everything waits
    _, before = status_json(QUEUE_PATH=str(queue))
    assert before["drops"].get("thinned", 0) > 0, before["drops"]
    stub.start()
    try:
        drained = run_cli(
            "drain", "--timeout", "120", QUEUE_PATH=str(queue), PHYCLOUD_ENDPOINT=stub.endpoint
        )
        assert drained.returncode == 0, drained.stderr
        events = stub.events()
    finally:
        stub.stop()
    (parts,) = incidents(events).values()
    assert [e["event_id"] for e in events[: len(parts)]] == [p["event_id"] for p in parts]
    incident = parts[0]["incident"]
    assert bag_seconds(incident["trigger"]["at"]) == error_at_s
    assert bag_seconds(incident["window"]["start"]) == error_at_s - 30
    assert bag_seconds(incident["window"]["end"]) == error_at_s + 10
    odom = joined(parts, "/odom")
    times = [bag_seconds(s["t"]) for s in odom]
    assert times == [error_at_s - 30 + k / odom_hz for k in range(40 * odom_hz + 1)]
    for sample, at in zip(odom, times, strict=True):
        assert sample["linear_velocity"]["x_mps"] == speed_of(round(at * odom_hz)), at
    first_hour = [
        e
        for e in events[len(parts) :]
        if e["event_type"] == "telemetry.periodic" and bag_seconds(e["captured_at"]) < 3600
    ]
    assert 0 < len(first_hour) < 3600  # there, thinned, and after the incident
