"""Real rosbag2 files with pauses: a bag whose two /odom messages are 11.6 days apart,
replayed as fast as possible, must not become hundreds of thousands of events, and a
replay stops at SIGTERM wherever it is."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.processes import python_env, status_json, wait_for

pytest.importorskip("rosbags", reason="bag replay needs rosbags (pip install .[bag])")

DAY_NS = 86_400 * 10**9
START_NS = 1_763_000_000 * 10**9


def write_odometry_bag(path: Path, stamps_ns: list[int]) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    with Writer(path, version=9) as writer:
        connection = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        for i, stamp in enumerate(stamps_ns):
            header = types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](
                    sec=stamp // 10**9, nanosec=stamp % 10**9
                ),
                frame_id="odom",
            )
            msg = types["nav_msgs/msg/Odometry"](
                header=header,
                child_frame_id="base_link",
                pose=types["geometry_msgs/msg/PoseWithCovariance"](
                    pose=types["geometry_msgs/msg/Pose"](
                        position=types["geometry_msgs/msg/Point"](x=float(i), y=0.0, z=0.0),
                        orientation=types["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=0.0, w=1.0
                        ),
                    ),
                    covariance=__import__("numpy").zeros(36),
                ),
                twist=types["geometry_msgs/msg/TwistWithCovariance"](
                    twist=types["geometry_msgs/msg/Twist"](
                        linear=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                        angular=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    ),
                    covariance=__import__("numpy").zeros(36),
                ),
            )
            writer.write(connection, stamp, store.serialize_cdr(msg, "nav_msgs/msg/Odometry"))


def replay(bag: Path, tmp_path: Path, **env: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "phytrace_edge", "run", "--input", f"bag:{bag}", "--rate", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=python_env(QUEUE_PATH=str(tmp_path / "q.db"), **env),
    )


def status(tmp_path: Path) -> dict:
    return status_json(QUEUE_PATH=str(tmp_path / "q.db"))[1]


def test_a_days_long_gap_is_skipped_not_ticked_through(tmp_path: Path, stub) -> None:
    bag = tmp_path / "gap"
    write_odometry_bag(bag, [START_NS, START_NS + int(11.6 * DAY_NS)])
    process = replay(bag, tmp_path, PHYCLOUD_ENDPOINT=stub.endpoint, FLUSH_INTERVAL_S="0.2")
    out, err = process.communicate(timeout=120)
    assert process.returncode == 0, err[-2000:]
    assert "1 gap(s) skipped, the longest 1002240 s" in out
    built = int(out.split("; ")[1].split()[0])
    # the first message is fresh for STALE_AFTER_S (5 s at 5 Hz), the last for none
    assert 1 <= built <= 30, out
    doc = status(tmp_path)
    assert doc["events_built"] == doc["queued_total"] == built
    assert "writer_backlog" not in doc["drops"]


def test_sigterm_stops_a_replay_wherever_it_is(tmp_path: Path, stub) -> None:
    bag = tmp_path / "long"
    step = 10**9 // 50  # odometry at 50 Hz for an hour: 180,000 messages
    write_odometry_bag(bag, [START_NS + i * step for i in range(180_000)])
    process = replay(bag, tmp_path, PHYCLOUD_ENDPOINT=stub.endpoint)
    try:
        wait_for(lambda: stub.stats()["unique"] > 100, 60, "the replay to be under way")
        process.send_signal(signal.SIGTERM)
        started = time.monotonic()
        out, err = process.communicate(timeout=60)
        took = time.monotonic() - started
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err[-2000:]
    assert took < 30  # a bound on ignoring SIGTERM, not a speed figure
    assert "stopped before the end" in out
    doc = status(tmp_path)
    assert not doc["running"] and doc["events_built"] == doc["queued_total"]
