"""From the simulated robot through the mock rclpy layer, handlers and builder to events."""

from __future__ import annotations

import subprocess
import sys
import time

import orjson
import pytest

from phytrace_edge import run_simulation
from phytrace_edge.config import load_settings
from phytrace_edge.udm.schema import find_violation

ALL_TOPICS = [
    "/battery_state",
    "/cmd_vel",
    "/delivery/status",
    "/diagnostics",
    "/goal_pose",
    "/gps/fix",
    "/imu/data",
    "/joint_states",
    "/odom",
    "/scan",
]


@pytest.fixture(scope="module")
def long_run() -> tuple[dict, list[dict]]:
    """Two simulated minutes, enough for a delivery and some faults."""
    events: list[dict] = []
    stats = run_simulation(1200, sink=events.append, seed=7)
    return stats, events


def test_reference_api_returns_the_documented_stats() -> None:
    events: list[dict] = []
    started = time.monotonic()
    stats = run_simulation(num_ticks=100, sink=events.append)
    took = time.monotonic() - started
    assert set(stats) == {"events_sent", "events_failed", "topics_seen", "duration_s"}
    assert stats["events_failed"] == 0 and stats["events_sent"] == len(events)
    # 100 ticks at 10 Hz = 10 s of robot time; 5 Hz sampling (besides, the robot's log)
    assert 48 <= sum(e["event_type"] == "telemetry.periodic" for e in events) <= 50
    assert stats["topics_seen"] == ALL_TOPICS
    assert 0 < stats["duration_s"] <= round(took, 3)  # the run's own wall time, not more


def test_every_event_is_schema_valid_and_unique(long_run: tuple[dict, list[dict]]) -> None:
    stats, events = long_run
    assert stats["events_sent"] == len(events) > 500
    assert all(find_violation(event) is None for event in events)
    assert len({event["event_id"] for event in events}) == len(events)
    assert [e["captured_at"] for e in events] == sorted(e["captured_at"] for e in events)


def test_values_vary_over_time(long_run: tuple[dict, list[dict]]) -> None:
    _, events = long_run
    xs = {round(e["location"]["local"]["x_m"], 1) for e in events if "location" in e}
    soc = [e["power"]["battery"]["state_of_charge_pct"] for e in events if "power" in e]
    assert len(xs) > 50
    assert soc[-1] < soc[0]
    states = {e["payload"]["delivery_state"] for e in events if "payload" in e}
    assert {"loading", "in_transit", "delivered", "returning"} <= states


def test_faults_and_transitions_reach_events(long_run: tuple[dict, list[dict]]) -> None:
    _, events = long_run
    errors = [err for e in events for err in e.get("operational", {}).get("errors", [])]
    transitions = [t for e in events for t in e.get("operational", {}).get("transitions", [])]
    assert any(err["level"] == "warn" for err in errors)
    assert any(err["level"] == "error" for err in errors)
    assert ("in_transit", "arriving") in {(t.get("from"), t["to"]) for t in transitions}
    lidar = [e["perception"]["lidar"][0] for e in events if "perception" in e]
    assert all(scan["valid_points"] < scan["num_points"] == 360 for scan in lidar)


def test_identity_settings_reach_every_event() -> None:
    settings = load_settings(
        env={"SOURCE_ID": "sim-7", "SOURCE_TYPE": "amr", "FLEET_ID": "f1", "SITE_ID": "s1"}
    ).settings
    events: list[dict] = []
    run_simulation(20, settings=settings, sink=events.append)
    assert events
    assert all(
        e["identity"]
        == {"source_id": "sim-7", "source_type": "amr", "fleet_id": "f1", "site_id": "s1"}
        for e in events
    )


def test_disabled_topics_are_not_subscribed() -> None:
    settings = load_settings(env={"TOPICS_DISABLED": "/scan,/gps/fix"}).settings
    events: list[dict] = []
    stats = run_simulation(30, settings=settings, sink=events.append)
    assert "/scan" not in stats["topics_seen"] and "/gps/fix" not in stats["topics_seen"]
    assert all("lidar" not in e.get("perception", {}) for e in events)


def test_a_failing_sink_counts_failed_events() -> None:
    def refuse(event: dict) -> None:
        raise OSError("disk full")

    stats = run_simulation(20, sink=refuse)
    assert stats["events_sent"] == 0 and stats["events_failed"] >= 9


def test_sim_command_prints_stats() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "sim", "--ticks", "50"],
        capture_output=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    stats = orjson.loads(result.stdout)
    assert stats["events_sent"] >= 23 and stats["topics_seen"] == ALL_TOPICS
