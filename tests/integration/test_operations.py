"""Operating the bridge as a process: run, status, drain, signals, metrics, logs.

Every test starts `phytrace-edge run` as a subprocess against the real stub and
observes it from outside, the way an operator or a health check would."""

from __future__ import annotations

import re
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import httpx
import orjson
import pytest

from phytrace_edge._version import __version__
from phytrace_edge.cli.run import DUPLICATE_SIGNAL_S
from tests.processes import BridgeProcess, free_port, run_cli, status_json, wait_for

SECRET = "phk_live_never_print_me"


def env_for(tmp_path: Path, endpoint: str, **extra: str) -> dict[str, str]:
    return {
        "PHYCLOUD_ENDPOINT": endpoint,
        "PHYCLOUD_API_KEY": SECRET,
        "QUEUE_PATH": str(tmp_path / "queue.db"),
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "20",
        "FLUSH_INTERVAL_S": "0.3",
        "RETRY_MIN_S": "0.05",
        "RETRY_MAX_S": "0.5",
        **extra,
    }


def status(env: dict[str, str]) -> tuple[int, dict]:
    return status_json(**env)


@pytest.fixture
def running(tmp_path: Path, stub):
    env = env_for(tmp_path, stub.endpoint)
    bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()

    def healthy_and_sending() -> bool:
        code, doc = status(env)
        rate = doc.get("topics", {}).get("/odom", {}).get("rate_hz", 0)
        return code == 0 and doc["sent_total"] > 0 and rate > 0  # rates need two heartbeats

    wait_for(healthy_and_sending, 60, "a healthy, sending bridge")
    yield bridge, env
    bridge.stop()


def test_status_while_running_and_after_a_clean_stop(running, tmp_path: Path, stub) -> None:
    bridge, env = running
    code, doc = status(env)
    assert code == 0 and doc["healthy"] and doc["running"]
    for key in ("depth", "bytes", "oldest_age_s"):
        assert key in doc["queue"]
    for key in (
        "drops",
        "dead_letters",
        "queued_total",
        "sent_total",
        "send_rate_eps",
        "last_success_at",
        "last_error",
        "heartbeat_age_s",
    ):
        assert key in doc
    assert doc["heartbeat_age_s"] < 5
    assert doc["topics"]["/odom"]["rate_hz"] > 0
    table = run_cli("status", **env)
    assert table.returncode == 0 and table.stdout.startswith("phytrace-edge status: HEALTHY")

    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=30) == 0
    code, doc = status(env)
    assert code == 3 and doc["running"] is False and doc["heartbeat_age_s"] is not None
    assert doc["queue"]["depth"] == 0, "SIGTERM flushes what was built"
    assert stub.stats()["unique"] == doc["sent_total"] == doc["queued_total"]
    assert doc["events_built"] == doc["queued_total"]  # the final figures, written at stop
    assert all(t["rate_hz"] == 0 for t in doc["topics"].values())  # nothing heard now
    assert doc["topics"]["/odom"]["last_seen_age_s"] >= doc["heartbeat_age_s"]
    log = (tmp_path / "bridge.log").read_text()
    assert "stopped; 0 event(s) left" in log
    assert SECRET not in log + table.stdout + orjson.dumps(doc).decode()


def test_status_without_a_queue(tmp_path: Path) -> None:
    result = run_cli("status", QUEUE_PATH=str(tmp_path / "none.db"))
    assert result.returncode == 3 and "never ran" in result.stderr


def not_a_queue(tmp_path: Path, kind: str) -> Path:
    """A path that is not a readable queue, of the given kind."""
    path = tmp_path / kind
    if kind == "directory":
        path.mkdir()
    elif kind == "text file":
        path.write_text("hello\n" * 100)
    elif kind == "foreign sqlite":
        with sqlite3.connect(path) as db:
            db.execute("CREATE TABLE photos(id INTEGER PRIMARY KEY, name TEXT)")
    elif kind == "corrupt sqlite":
        with sqlite3.connect(path) as db:
            db.execute("CREATE TABLE counters(name TEXT PRIMARY KEY, value INTEGER)")
            db.executemany("INSERT INTO counters VALUES (?, ?)", [(str(i), i) for i in range(500)])
        data = bytearray(path.read_bytes())
        data[100:4096] = b"\xff" * (4096 - 100)  # the first page's b-tree header is gone
        path.write_bytes(bytes(data))
    elif kind == "char device":
        return Path("/dev/null")
    return path


@pytest.mark.parametrize(
    "kind", ["directory", "text file", "foreign sqlite", "corrupt sqlite", "char device"]
)
def test_status_on_a_path_that_is_not_a_queue_is_one_line(tmp_path: Path, kind: str) -> None:
    path = not_a_queue(tmp_path, kind)
    mode = path.stat().st_mode
    result = run_cli("status", QUEUE_PATH=str(path))
    assert result.returncode == 4, result.stderr
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert result.stderr.startswith(f"phytrace-edge: error: queue {path}: ")
    assert path.stat().st_mode == mode  # status never changes what it reads


def test_status_is_unhealthy_when_the_key_is_refused(tmp_path: Path, stub) -> None:
    stub.set_faults(fixed_status=401)
    env = env_for(tmp_path, stub.endpoint)
    bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
    try:
        _, doc = wait_for(lambda: (r := status(env))[0] == 1 and r, 60, "unhealthy status")
        assert any("PHYCLOUD_API_KEY" in problem for problem in doc["problems"])
        assert doc["auth_failures"] > 0 and doc["drops"] == {}
    finally:
        bridge.stop()


def test_drain_ships_a_backlog_left_by_a_stopped_bridge(tmp_path: Path, stub) -> None:
    stub.set_faults(fixed_status=503)
    env = env_for(tmp_path, stub.endpoint)
    bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
    wait_for(lambda: status(env)[1].get("queue", {}).get("depth", 0) > 30, 60, "a backlog")
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=30) == 0
    left = status(env)[1]["queue"]["depth"]
    assert left > 30

    timed_out = run_cli("drain", "--timeout", "2", **env)
    assert timed_out.returncode == 1, timed_out.stdout + timed_out.stderr
    said = rf"sent 0 event\(s\) in \d+\.\d s; {left} left \(HTTP 503\)\n"
    assert re.fullmatch(said, timed_out.stdout), timed_out.stdout

    stub.set_faults(fixed_status=None)
    drained = run_cli("drain", **env)
    assert drained.returncode == 0, drained.stdout + drained.stderr
    said = rf"drained {left} event\(s\) in \d+\.\d s; the queue is empty\n"
    assert re.fullmatch(said, drained.stdout), drained.stdout
    assert status(env)[1]["queue"]["depth"] == 0
    assert stub.stats()["unique"] == status(env)[1]["queued_total"]


def test_drain_while_the_service_runs_never_double_sends(running, stub) -> None:
    bridge, env = running
    for _ in range(3):
        assert run_cli("drain", "--timeout", "20", **env).returncode in (0, 1)
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=30) == 0
    stats = stub.stats()
    assert stats["duplicates"] == 0 and stats["unique"] == status(env)[1]["queued_total"]


def test_a_second_signal_exits_at_once_and_the_queue_stays_sound(
    tmp_path: Path, stub_factory
) -> None:
    stub = stub_factory("--latency", "30")  # the flush would hang on every request
    env = env_for(tmp_path, stub.endpoint, SHUTDOWN_GRACE_S="60", HTTP_TIMEOUT_S="60")
    log = tmp_path / "bridge.log"
    bridge = BridgeProcess(log, **env).start()
    wait_for(lambda: f"phytrace-edge {__version__}:" in log.read_text(), 30, "start-up")
    wait_for(lambda: status(env)[1].get("queue", {}).get("depth", 0) > 5, 30, "queued events")
    bridge.signal(signal.SIGTERM)
    first = time.monotonic()
    bridge.signal(signal.SIGTERM)  # the same request twice (Ctrl-C under ros2 launch)
    wait_for(lambda: "stopping (again to exit at once)" in log.read_text(), 10, "first signal")
    assert bridge.process.poll() is None  # still flushing: the duplicate was ignored
    # a second request, once the duplicate window has passed, exits at once
    wait_for(lambda: time.monotonic() - first > DUPLICATE_SIGNAL_S, 10, "the window to pass")
    started = time.monotonic()
    bridge.signal(signal.SIGTERM)
    code = bridge.wait(timeout=10)
    assert code == 128 + signal.SIGTERM and time.monotonic() - started < 5
    result = (
        subprocess.run(
            ["sqlite3", str(tmp_path / "queue.db"), "PRAGMA integrity_check"],
            capture_output=True,
            text=True,
        )
        if Path("/usr/bin/sqlite3").exists()
        else None
    )
    assert result is None or result.stdout.strip() == "ok"
    assert status(env)[1]["queue"]["depth"] > 0  # kept for the next run


def test_metrics_endpoint_and_json_logs(tmp_path: Path, stub) -> None:
    port = free_port()
    env = env_for(tmp_path, stub.endpoint, METRICS_PORT=str(port), LOG_FORMAT="json")
    log = tmp_path / "bridge.log"
    bridge = BridgeProcess(log, **env).start()
    try:

        def scraped() -> str | None:
            try:
                text = httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=2).text
            except httpx.HTTPError:
                return None
            sent = "phytrace_events_sent_total" in text
            return text if sent and "phytrace_events_sent_total 0.0" not in text else None

        metrics = wait_for(scraped, 60, "metrics with sent events")
        for name in (
            "phytrace_queue_depth",
            "phytrace_queue_bytes",
            "phytrace_queue_oldest_age_seconds",
            "phytrace_events_built_total",
            "phytrace_events_queued_total",
            "phytrace_events_dropped_total",
            "phytrace_send_latency_seconds_bucket",
            "phytrace_send_retries_total",
            "phytrace_unexpected_answers_total 0.0",  # the stub's answers add up
            'phytrace_topic_messages_total{topic="/odom"}',
            'phytrace_topic_last_seen_age_seconds{topic="/scan"}',
        ):
            assert name in metrics, name
    finally:
        bridge.signal(signal.SIGTERM)
        assert bridge.wait(timeout=30) == 0
    lines = log.read_text().splitlines()
    records = [orjson.loads(line) for line in lines]
    assert {"ts", "level", "logger", "message"} <= set(records[0])
    assert SECRET not in log.read_text()
