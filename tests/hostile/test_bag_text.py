"""Real rosbag2 files with broken text, replayed by ``phytrace-edge run --input bag:``
into the stub (issue 31): a /delivery/status whose JSON escapes a lone surrogate is
kept with U+FFFD and counted ``text_repaired``; a record whose string is not UTF-8 is
skipped and counted ``undecodable``, and the replay goes on to the end. Every other
message's state change reaches PhyCloud."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from tests.processes import python_env, status_json

pytest.importorskip("rosbags", reason="bag replay needs rosbags (pip install .[bag])")

START_NS = 1_763_000_000 * 10**9
STATES = 10  # /delivery/status messages, one a second, each a new state
FFFD = "\ufffd"


def delivery_json(index: int) -> str:
    """The JSON text of status ``index``; json.dumps escapes a lone surrogate as
    ``\\ud800``, which is valid JSON."""
    if index == 4:
        return json.dumps({"order_id": "o-1", "state": "s4 \ud800"})
    if index == 7:  # the lone surrogate in a key
        return json.dumps({"order_id": "o-1", "state": "s7", "\udfff": "x"})
    return json.dumps({"order_id": "o-1", "state": f"s{index}"})


def write_status_bag(path: Path, texts: list[str], broken: int | None = None) -> None:
    """``texts`` on /delivery/status, one a second, then one /odom message a second
    later (a replay ticks up to its last message: this gives the last status its
    tick). The record ``broken`` has two bytes of its state replaced by 0xff 0xfe,
    which no UTF-8 decoder accepts; the CDR string keeps its length."""
    import numpy as np
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    with Writer(path, version=9) as writer:
        status = writer.add_connection("/delivery/status", "std_msgs/msg/String", typestore=store)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        string = types["std_msgs/msg/String"]
        for index, text in enumerate(texts):
            raw = bytes(store.serialize_cdr(string(data=text), status.msgtype))
            if index == broken:  # "s<i>" -> 0xff 0xfe: as long, so the CDR length holds
                at = raw.index(f'"s{index}"'.encode()) + 1
                raw = raw[:at] + b"\xff\xfe" + raw[at + 2 :]
            writer.write(status, START_NS + index * 10**9, raw)
        stamp = START_NS + len(texts) * 10**9
        header = types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=0),
            frame_id="odom",
        )
        vector = types["geometry_msgs/msg/Vector3"]
        msg = types["nav_msgs/msg/Odometry"](
            header=header,
            child_frame_id="base_link",
            pose=types["geometry_msgs/msg/PoseWithCovariance"](
                pose=types["geometry_msgs/msg/Pose"](
                    position=types["geometry_msgs/msg/Point"](x=1.0, y=0.0, z=0.0),
                    orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                ),
                covariance=np.zeros(36),
            ),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=types["geometry_msgs/msg/Twist"](
                    linear=vector(x=0.0, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0)
                ),
                covariance=np.zeros(36),
            ),
        )
        writer.write(odom, stamp, store.serialize_cdr(msg, odom.msgtype))


def replay(bag: Path, tmp_path: Path, endpoint: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "run", "--input", f"bag:{bag}", "--rate", "0"],
        capture_output=True,
        text=True,
        timeout=120,
        env=python_env(
            PHYCLOUD_ENDPOINT=endpoint, QUEUE_PATH=str(tmp_path / "q.db"), FLUSH_INTERVAL_S="0.2"
        ),
    )


def transitions(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The delivery state changes PhyCloud holds, in bag time order."""
    found = [
        transition
        for event in events
        for transition in event.get("operational", {}).get("transitions", [])
    ]
    return sorted(found, key=lambda t: t["at"])


def test_an_escaped_lone_surrogate_is_repaired_and_every_status_arrives(
    tmp_path: Path, stub
) -> None:
    bag = tmp_path / "surrogates"
    write_status_bag(bag, [delivery_json(i) for i in range(STATES)])

    result = replay(bag, tmp_path, stub.endpoint)

    assert result.returncode == 0, result.stderr[-2000:]
    assert "stopped early" not in result.stdout and "undecodable" not in result.stdout
    assert result.stdout.startswith(f"replayed {bag}: 11 messages ")
    states = [f"s{i}" for i in range(STATES)]
    states[4] = f"s4 {FFFD}"
    arrived = transitions(stub.events())
    assert [t["to"] for t in arrived] == states
    assert [t.get("from") for t in arrived] == [None, *states[:-1]]
    # a tick every 200 ms of bag time from the first message to the last, 10 s later
    assert Counter(e["event_type"] for e in stub.events()) == {"telemetry.periodic": 50}
    _, doc = status_json(QUEUE_PATH=str(tmp_path / "q.db"))
    topic = doc["topics"]["/delivery/status"]
    assert topic["received"] == STATES
    assert topic["rejected"] == {"text_repaired": 2}  # messages 4 and 7, both kept
    assert doc["topics"]["/odom"]["rejected"] == {}
    assert doc["events_built"] == doc["queued_total"] == doc["sent_total"] == 50


def test_a_record_that_is_not_utf8_is_skipped_and_the_replay_goes_on(tmp_path: Path, stub) -> None:
    bag = tmp_path / "not-utf8"
    write_status_bag(
        bag, [json.dumps({"order_id": "o-1", "state": f"s{i}"}) for i in range(STATES)], broken=6
    )

    result = replay(bag, tmp_path, stub.endpoint)

    assert result.returncode == 0, result.stderr[-2000:]
    assert "stopped early" not in result.stdout
    assert "; 1 undecodable message(s) skipped (/delivery/status 1)" in result.stdout
    # one warning when it happened (the dispatcher's, at most one a minute), one summary
    warnings = [line for line in result.stderr.splitlines() if "undecodable" in line]
    assert len(warnings) == 2, result.stderr[-2000:]
    assert "message rejected (undecodable, 1 so far)" in warnings[0]
    assert "'utf-8' codec can't decode byte 0xff" in warnings[0]
    assert "WARNING" in warnings[1] and f"replayed {bag}: 11 messages" in warnings[1]
    states = [f"s{i}" for i in range(STATES) if i != 6]
    arrived = transitions(stub.events())
    assert [t["to"] for t in arrived] == states
    assert [t.get("from") for t in arrived] == [None, *states[:-1]]  # s5 -> s7
    assert Counter(e["event_type"] for e in stub.events()) == {"telemetry.periodic": 50}
    _, doc = status_json(QUEUE_PATH=str(tmp_path / "q.db"))
    topic = doc["topics"]["/delivery/status"]
    assert topic["received"] == STATES  # read from the bag, one of them undecodable
    assert topic["rejected"] == {"undecodable": 1}
    assert doc["events_built"] == doc["queued_total"] == doc["sent_total"] == 50
