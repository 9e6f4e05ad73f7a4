"""``phytrace-edge mark`` against a running bridge (the simulated robot, in real time)
and a real stub: the answer, the incident at PhyCloud, what ``status`` counts, and the
answers when nothing can be recorded."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from phytrace_edge.runtime.marks import marks_dir
from phytrace_edge.udm.event import parse_timestamp
from tests.processes import BridgeProcess, StubProcess, run_cli, status_json, wait_for


@pytest.fixture
def bridge(tmp_path: Path, stub: StubProcess) -> Any:
    """``start(**settings)``: the simulated robot's bridge, marks its only triggers."""
    started: list[BridgeProcess] = []

    def start(**settings: str) -> BridgeProcess:
        env = {
            "BRIDGE_INPUT": "sim",
            "PHYCLOUD_ENDPOINT": stub.endpoint,
            "QUEUE_PATH": str(tmp_path / "q.db"),
            "FLUSH_INTERVAL_S": "0.2",
            "INCIDENT_BEFORE_S": "2",
            "INCIDENT_AFTER_S": "1",
            "INCIDENT_DIAGNOSTICS_LEVEL": "off",
            "INCIDENT_ROSOUT_LEVEL": "off",
            "HEALTH_EVENT_INTERVAL_S": "0",
            **settings,
        }
        process = BridgeProcess(tmp_path / "bridge.log", **env).start()
        started.append(process)
        wait_for(
            lambda: status_json(QUEUE_PATH=env["QUEUE_PATH"])[1].get("running"),
            60,
            "the bridge to run",
        )
        return process

    yield start
    for process in started:
        process.stop()


def mark(queue: Path, reason: str, *flags: str) -> tuple[int, str, str]:
    done = run_cli("mark", "--reason", reason, *flags, QUEUE_PATH=str(queue))
    return done.returncode, done.stdout.strip(), done.stderr.strip()


def incident_parts(stub: StubProcess, incident: str) -> list[dict[str, Any]]:
    parts = [
        e
        for e in stub.events()
        if e["event_type"] == "incident" and e["incident"]["id"] == incident
    ]
    return sorted(parts, key=lambda e: e["incident"]["part"])


def test_a_mark_records_the_window_around_it(
    bridge: Any, stub: StubProcess, tmp_path: Path
) -> None:
    bridge()
    queue = tmp_path / "q.db"
    code, out, err = mark(queue, "operator saw the robot wobble")
    assert code == 0, err
    assert out.startswith("incident ") and out.endswith(": it is sent once its window ends")
    incident = out.split()[1]

    def arrived() -> list[dict[str, Any]] | None:
        parts = incident_parts(stub, incident)
        return parts if parts and len(parts) == parts[0]["incident"]["parts"] else None

    parts = wait_for(arrived, 30, "the incident at the stub")
    body = parts[0]["incident"]
    assert body["trigger"]["kind"] == "manual"
    assert body["trigger"]["message"] == "operator saw the robot wobble"
    start, end = (parse_timestamp(body["window"][k]) for k in ("start", "end"))
    assert end - start == pytest.approx(3.0, abs=0.01)  # 2 s before, 1 s after
    odom = [s for part in parts for s in part["incident"]["samples"].get("/odom", [])]
    # the window is said to the millisecond, the samples' times to the microsecond
    assert odom and all(start - 0.001 <= parse_timestamp(s["t"]) <= end + 0.001 for s in odom)
    assert list(marks_dir(queue).iterdir()) == []  # the mark and its answer are gone

    def counted() -> dict[str, Any] | None:
        incidents = status_json(QUEUE_PATH=str(queue))[1].get("incidents", {})
        return incidents if incidents.get("parts_sent", 0) >= len(parts) else None

    incidents = wait_for(counted, 30, "status to count the incident sent")
    assert incidents["recorded"] == 1 and incidents["triggers"] == 1
    assert incidents["parts"] == len(parts) and incidents["rate_limited"] == 0
    lines = run_cli("status", QUEUE_PATH=str(queue)).stdout.splitlines()
    (line,) = [line for line in lines if line.startswith("  incidents ")]
    n = len(parts)
    assert line.startswith(f"  incidents    1 recorded ({n} part(s), {n} sent); window ")


def test_a_mark_inside_an_open_window_extends_it(
    bridge: Any, stub: StubProcess, tmp_path: Path
) -> None:
    bridge(INCIDENT_AFTER_S="20")
    queue = tmp_path / "q.db"
    code, first, _ = mark(queue, "first")
    assert code == 0
    code, second, _ = mark(queue, "second")
    assert code == 0
    assert second.startswith(f"incident {first.split()[1]} was already being recorded")


def test_a_mark_beyond_the_hourly_limit_is_refused_and_counted(bridge: Any, tmp_path: Path) -> None:
    bridge(INCIDENT_MAX_PER_HOUR="1", INCIDENT_AFTER_S="0.2")
    queue = tmp_path / "q.db"
    assert mark(queue, "first")[0] == 0

    def closed() -> bool:
        return status_json(QUEUE_PATH=str(queue))[1].get("incidents", {}).get("recorded") == 1

    wait_for(closed, 30, "the first incident closed")
    code, out, err = mark(queue, "second")
    assert (code, out) == (1, "")
    assert err == (
        "phytrace-edge: error: the bridge took the mark but recorded nothing: "
        "INCIDENT_MAX_PER_HOUR incidents were recorded in the last hour "
        "(status counts it as rate-limited)"
    )
    wait_for(
        lambda: status_json(QUEUE_PATH=str(queue))[1]["incidents"].get("rate_limited") == 1,
        30,
        "status to count the refused mark",
    )


def test_a_mark_with_recording_off_says_so(bridge: Any, tmp_path: Path) -> None:
    bridge(INCIDENT_RECORDING="false")
    code, _, err = mark(tmp_path / "q.db", "anything")
    assert code == 1
    assert err.endswith("incident recording is off on this bridge (INCIDENT_RECORDING=false)")


def test_a_mark_no_bridge_takes_is_taken_back(tmp_path: Path) -> None:
    queue = tmp_path / "q.db"
    marks_dir(queue).mkdir(parents=True)
    code, out, err = mark(queue, "nobody listens", "--wait", "0.5")
    assert (code, out) == (3, "")
    assert "no running bridge took the mark within 0.5 s" in err
    assert list(marks_dir(queue).iterdir()) == []
