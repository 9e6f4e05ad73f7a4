"""Replay of rosbag2 files (.mcap and .db3) written with rosbags: events on the bag's
timeline with the recorded values, unknown types skipped with a count, damaged bags
reported, not crashed on."""

from __future__ import annotations

import subprocess
import sys
import threading
from collections import Counter
from pathlib import Path

import pytest

from phytrace_edge import run_simulation
from phytrace_edge.builder.assemble import DOMAINS
from phytrace_edge.config import Settings
from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.sources.bag import BagSource, ReplaySummary
from phytrace_edge.runtime import options, wiring
from phytrace_edge.sim.recorder import CUSTOM_TOPIC, record_simulation
from phytrace_edge.udm.schema import find_violation
from tests.processes import python_env

pytest.importorskip("rosbags", reason="bag replay needs rosbags (pip install .[bag])")
SECONDS = 10


@pytest.fixture(scope="module", params=["mcap", "sqlite3"])
def bag(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bags") / f"robot-{request.param}"
    counts = record_simulation(path, SECONDS, storage=request.param, seed=0)
    assert counts["/odom"] >= SECONDS * 10 - 1 and counts[CUSTOM_TOPIC] > 0
    return path


def replay_events(path: Path, rate: float = 0) -> tuple[list[dict], ReplaySummary]:
    """The periodic events of a replay through the pipeline ``run --input bag:`` uses."""
    settings = Settings().replace(bridge_input=f"bag:{path}", replay_rate=rate, stale_after_s=5.0)
    source = BagSource(options.source_options(settings, {}))
    events: list[dict] = []
    pipeline = wiring.build_pipeline(settings, source, lambda built: events.append(built.event))
    pipeline.open()
    pipeline.ingest(threading.Event(), lambda: None)
    pipeline.close()
    assert source.summary is not None
    return [e for e in events if e["event_type"] == "telemetry.periodic"], source.summary


def comparable(event: dict) -> dict:
    """The values an event carries, without ids, times and ages."""
    out = {}
    for domain in DOMAINS:
        body = {
            k: v
            for k, v in event.get(domain, {}).items()
            if k not in ("sources", "transitions", "new_goals", "errors")
        }
        if domain == "navigation":
            body.get("goal", {}).pop("received_at", None)
        out[domain] = body
    return out


def test_replay_gives_the_recorded_values_on_the_bag_timeline(bag: Path) -> None:
    events, summary = replay_events(bag)
    live: list[dict] = []
    run_simulation(SECONDS * 10, sink=live.append, seed=0)
    live = [e for e in live if e["event_type"] == "telemetry.periodic"]

    assert summary.error is None
    assert sum(summary.messages.values()) > 500
    assert summary.skipped == {  # not configured: TOPICS_EXTRA is empty
        f"{CUSTOM_TOPIC} (acme_msgs/msg/Widget)": summary.messages["/battery_state"],
        "/motor/temperature (sensor_msgs/msg/Temperature)": summary.messages["/battery_state"],
    }  # the recorder writes one widget per battery message
    assert all(find_violation(event) is None for event in events)
    # the same seeded robot, live and replayed, gives the same values at every tick
    assert len(events) >= len(live) - 1
    for replayed, original in zip(events, live, strict=False):
        assert comparable(replayed) == comparable(original)
    stamps = [e["captured_at"] for e in events]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)


def test_captured_at_is_bag_time(bag: Path) -> None:
    events, _ = replay_events(bag)
    first_odom = events[0]["location"]["sources"][0]
    assert first_odom["clock"] == "epoch"
    # a tick comes 200 ms of bag time after the first message, not at replay time
    assert events[0]["captured_at"] >= first_odom["stamp"]
    assert events[0]["captured_at"] < events[-1]["captured_at"]


def test_replay_at_a_rate_keeps_to_the_bag_pace(bag: Path) -> None:
    events, summary = replay_events(bag, rate=50)  # 10 s of bag in about 0.2 s
    assert summary.error is None and len(events) >= SECONDS * 5 - 1


def test_a_truncated_bag_is_reported_not_crashed_on(bag: Path, tmp_path: Path) -> None:
    damaged = tmp_path / bag.name
    damaged.mkdir()
    for file in bag.iterdir():
        data = file.read_bytes()
        keep = data if file.name == "metadata.yaml" else data[: len(data) * 6 // 10]
        (damaged / file.name).write_bytes(keep)
    try:
        events, summary = replay_events(damaged)
    except ConfigError as exc:  # some storages refuse to open at all: a clear message
        assert "not a readable rosbag2 or ROS 1 bag" in str(exc)
        return
    assert summary.error is not None or sum(summary.messages.values()) < 583
    assert all(find_violation(event) is None for event in events)


def test_a_missing_bag_is_a_one_line_error(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "phytrace_edge",
            "run",
            "--bridge-input",
            f"bag:{tmp_path / 'nope'}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=python_env(QUEUE_PATH=str(tmp_path / "q.db")),
    )
    assert result.returncode == 2
    assert result.stderr.strip().endswith("no such file or directory")
    assert result.stderr.count("\n") == 1


def test_run_replays_a_bag_into_phycloud(bag: Path, tmp_path: Path, stub) -> None:
    env = python_env(
        PHYCLOUD_ENDPOINT=stub.endpoint,
        QUEUE_PATH=str(tmp_path / "q.db"),
        FLUSH_INTERVAL_S="0.2",
        # a type defined only in the bag, at most every 2 s of bag time; the robot's log
        TOPICS_EXTRA=f"{CUSTOM_TOPIC} rate_hz=0.5",
        ROSOUT_MIN_LEVEL="info",
    )
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "phytrace_edge",
            "run",
            "--bridge-input",
            f"bag:{bag}",
            "--rate",
            "0",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.startswith(f"replayed {bag}: ")
    built = int(result.stdout.split("; ")[1].split()[0])
    events = stub.events()
    by_type = Counter(event["event_type"] for event in events)
    assert by_type["telemetry.periodic"] == built == SECONDS * 5 - 1
    widgets = [event for event in events if event["event_type"] == "telemetry.topic"]
    assert len(widgets) == SECONDS // 2  # one message a second, sent at most every 2 s
    assert {(w["topic"], w["type"]) for w in widgets} == {(CUSTOM_TOPIC, "acme_msgs/msg/Widget")}
    assert all(w["data"] == {"name": "w", "level": 1.0} for w in widgets)
    logs = [event for event in events if event["event_type"] == "log.record"]
    assert any(log["logger"] == "delivery_robot.mission" for log in logs), logs
    assert "bridge.health" not in by_type  # a replay is history: no health of its own
    first_tick, last_tick = (
        min(e["captured_at"] for e in events),
        max(e["captured_at"] for e in events),
    )
    assert all(first_tick <= w["captured_at"] <= last_tick for w in widgets)  # bag time
