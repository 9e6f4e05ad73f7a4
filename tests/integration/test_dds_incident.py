"""The ``dds`` input and incident windows (issue 35), against real Cyclone DDS on a private
domain confined to loopback: every message of the window's topics
(``SourceOptions.full_rate``) is delivered, all those waiting taken at the sample tick
(not only the newest), and their QoS is still matched as a state stream's (a
best-effort odometry writer matches); with INCIDENT_RECORDING=false only the newest is
taken at the tick, as before.

- ``phytrace-edge run --input dds`` in a process of its own, an odometry writer at
  50 Hz in this process, a /diagnostics ERROR or ``phytrace-edge mark``: the incident
  at the stub holds the window's odometry at full rate, with the values written.
- The input in this process (``DdsInput``) and ``dds_robot.py``: how many messages of
  a window topic and of a ``TOPICS_EXTRA`` one reach the dispatcher and the window,
  recording on and off; the QoS a window topic is read with.
"""

from __future__ import annotations

import copy
import threading
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("cyclonedds", reason="the DDS input needs cyclonedds (pip install .[dds])")

from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
from phytrace_edge.ingest.sources.dds_types import DDS_TYPES
from phytrace_edge.udm.event import parse_timestamp
from phytrace_edge.udm.schema import find_violation
from tests.integration.dds_publisher import BEST_EFFORT, RELIABLE, idl_sample
from tests.integration.test_dds_qos import DIAGNOSTICS, DdsRobot, error, started
from tests.integration.test_dds_source import private_loopback_domain
from tests.processes import BridgeProcess, run_cli, status_json, wait_for
from tests.ros.known import KNOWN

ODOM_HZ = 50.0
BEFORE_S, AFTER_S = 2.0, 1.0


def moved(fields: dict[str, Any], x: float) -> dict[str, Any]:
    """Odometry ``fields`` at ``x`` metres."""
    fields = copy.deepcopy(fields)
    fields["pose"]["pose"]["position"]["x"] = x
    return fields


def stamp(i: int) -> dict[str, int]:
    """Message i's stamp: i ms after the known one's second."""
    return {
        "sec": KNOWN["/odom"][2]["header"]["stamp"]["sec"] + i // 1000,
        "nanosec": (i % 1000) * 10**6,
    }


class OdometryWriter:
    """A best-effort odometry writer at ``ODOM_HZ`` in a thread of this process, as a
    sensor writes (paced by the clock, catching up after a late wake-up); message i
    is at x = i metres and stamped i ms after the known stamp, the other fields the
    known values. And a reliable /diagnostics writer, for the trigger."""

    def __init__(self, domain_id: int) -> None:
        # the Domain object carries the loopback-only configuration: kept with the writers
        self._domain = Domain(domain_id, domain_config(localhost_only=True))
        self._participant = DomainParticipant(domain_id)
        odom_type = DDS_TYPES[KNOWN["/odom"][0]]
        self._fields = KNOWN["/odom"][2]
        self._odom_type = odom_type
        odom_topic = Topic(self._participant, dds_topic_name("/odom"), odom_type)
        self.odom = DataWriter(self._participant, odom_topic, qos=BEST_EFFORT)
        diagnostics_type = DDS_TYPES[DIAGNOSTICS]
        self._diagnostics_type = diagnostics_type
        diagnostics_topic = Topic(
            self._participant, dds_topic_name("/diagnostics"), diagnostics_type
        )
        self.diagnostics = DataWriter(self._participant, diagnostics_topic, qos=RELIABLE)
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def message(self, i: int) -> Any:
        fields = moved(self._fields, float(i))
        fields["header"]["stamp"] = stamp(i)
        return idl_sample(self._odom_type, fields)

    def _run(self) -> None:
        start = time.monotonic()
        while True:
            self.odom.write(self.message(self.sent))
            self.sent += 1
            if self._stop.wait(max(0.0, start + self.sent / ODOM_HZ - time.monotonic())):
                return

    def start(self) -> None:
        self._thread.start()

    def write_error(self, name: str) -> None:
        self.diagnostics.write(idl_sample(self._diagnostics_type, error(name)))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10)


def incident_parts(events: list[dict[str, Any]]) -> list[dict[str, Any]] | None:
    """The parts of the one incident among ``events``, by ``incident.part``, once all
    came."""
    parts = sorted(
        (e for e in events if e["event_type"] == "incident"), key=lambda e: e["incident"]["part"]
    )
    if not parts or len(parts) != parts[0]["incident"]["parts"]:
        return None
    assert {p["incident"]["id"] for p in parts} == {parts[0]["incident"]["id"]}
    return parts


@pytest.mark.parametrize("trigger", ["diagnostics", "mark"])
def test_an_incident_holds_the_odometry_at_full_rate(
    tmp_path: Path, stub: Any, trigger: str
) -> None:
    """Odometry written at 50 Hz by a best-effort writer, the bridge's sample tick at
    1 Hz: on a /diagnostics ERROR (level 2) or a mark, the incident at the stub holds
    the odometry of its 3 s window (2 s before, 1 s after) at 40 Hz or more, each
    sample one message written (its x, its stamp, the known velocity), in order,
    none twice: delivered as each came, not one a second at the tick."""
    ros = private_loopback_domain()
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    writer = OdometryWriter(int(ros["ROS_DOMAIN_ID"]))
    bridge = BridgeProcess(
        log,
        BRIDGE_INPUT="dds",
        PHYCLOUD_ENDPOINT=stub.endpoint,
        PHYCLOUD_API_KEY="phk_test_secret_key",
        QUEUE_PATH=str(queue),
        SAMPLE_RATE_HZ="1",
        FLUSH_INTERVAL_S="0.2",
        HEALTH_EVENT_INTERVAL_S="0",
        INCIDENT_RECORDING="true",
        INCIDENT_BEFORE_S=str(BEFORE_S),
        INCIDENT_AFTER_S=str(AFTER_S),
        INCIDENT_ROSOUT_LEVEL="off",
        **ros,
    ).start()

    def alive() -> None:
        code = bridge.process.poll() if bridge.process else None
        assert code is None, f"the bridge exited ({code}):\n{log.read_text()[-3000:]}"

    try:

        def matched() -> bool:
            alive()
            return bool(writer.odom.get_matched_subscriptions()) and bool(
                writer.diagnostics.get_matched_subscriptions()
            )

        wait_for(matched, 60, "the bridge's readers to match the writers", every=0.1)
        writer.start()
        # the window's 2 s before the trigger, and more, written
        wait_for(lambda: writer.sent >= (BEFORE_S + 0.5) * ODOM_HZ, 30, "2.5 s of odometry")
        if trigger == "diagnostics":
            writer.write_error("motor-fault")
        else:
            done = run_cli("mark", "--reason", "x", QUEUE_PATH=str(queue))
            assert done.returncode == 0, done.stderr

        def arrived() -> list[dict[str, Any]] | None:
            alive()
            return incident_parts(stub.events())

        parts = wait_for(arrived, 60, "the incident at the stub", every=0.2)
        topics = status_json(QUEUE_PATH=str(queue))[1].get("topics", {})
    finally:
        writer.close()
        bridge.stop()
    for part in parts:
        assert find_violation(part) is None
    body = parts[0]["incident"]
    if trigger == "diagnostics":
        assert body["trigger"]["kind"] == "diagnostics"
        assert body["trigger"]["topic"] == "/diagnostics"
        assert body["trigger"]["message"].startswith("motor-fault")
    else:
        assert (body["trigger"]["kind"], body["trigger"]["message"]) == ("manual", "x")
    start, end = (parse_timestamp(body["window"][k]) for k in ("start", "end"))
    assert end - start == pytest.approx(BEFORE_S + AFTER_S, abs=0.01)
    assert "cut_short" not in body and "dropped" not in body
    odom = [s for part in parts for s in part["incident"]["samples"].get("/odom", [])]
    rate_hz = len(odom) / (end - start)
    assert rate_hz >= 40, (rate_hz, len(odom))
    # the window's ends are in ms, the samples' times in us
    assert all(start - 0.001 <= parse_timestamp(s["t"]) <= end + 0.001 for s in odom)
    xs = [s["local"]["x_m"] for s in odom]
    assert xs == sorted(set(xs)), "in order, none twice"
    assert all(x == int(x) and 0 <= x < writer.sent for x in xs), "messages written"
    known = KNOWN["/odom"][2]
    for sample in odom:
        i = int(sample["local"]["x_m"])
        assert sample["stamp_ns"] == stamp(i)["sec"] * 10**9 + stamp(i)["nanosec"]
        assert sample["local"]["y_m"] == known["pose"]["pose"]["position"]["y"]
        assert sample["linear_velocity"]["x_mps"] == known["twist"]["twist"]["linear"]["x"]
        assert sample["frame_id"] == "odom"
    # matched as a state stream: best effort (a reliable reader cannot match the writer)
    assert topics["/odom"]["qos"] == "best effort, volatile"
    assert topics["/odom"]["qos_incompatible"] == 0


TEMPERATURE = "sensor_msgs/msg/Temperature"
TEMPERATURE_FIELDS = {
    "header": {"stamp": {"sec": 1_763_000_000, "nanosec": 0}, "frame_id": "motor"},
    "temperature": 41.5,
    "variance": 0.25,
}


@pytest.mark.parametrize("recording", [True, False], ids=["recording", "not-recording"])
def test_window_topics_deliver_every_message_only_while_recording(
    tmp_path: Path, recording: bool
) -> None:
    """Odometry and an extra topic (rate_hz=1), both window topics, each written 75
    times at 50 Hz by reliable writers (so none is lost) into a 5 Hz sample tick:
    recording, every message reaches the dispatcher and the window holds each one
    once (a mark's incident: the values written, counted); not recording, the
    odometry is taken at the tick (one message a tick at most) and the extra topic
    when due (once a second), as before issue 35. Either way both are read with
    their writers' QoS, as state streams are."""
    ros = private_loopback_domain()
    robot = DdsRobot(ros, tmp_path / "robot.log")
    odom = robot.writer("/odom", KNOWN["/odom"][0], "reliable")
    sensor = robot.writer("/motor/temperature", TEMPERATURE, "reliable")
    heard = started(
        robot,
        ros,
        f"/motor/temperature type={TEMPERATURE} rate_hz=1",
        SAMPLE_RATE_HZ="5",
        INCIDENT_RECORDING=str(recording).lower(),
        INCIDENT_TOPICS="/odom,/motor/temperature",
        INCIDENT_AFTER_S="0.2",
    )
    received = heard.dispatcher.received
    writes = {
        "/odom": (odom, KNOWN["/odom"][2]),
        "/motor/temperature": (sensor, TEMPERATURE_FIELDS),
    }
    # the burst's messages, told from the warm-up's by their values
    burst = {
        "/odom": (odom, moved(KNOWN["/odom"][2], 777.0)),
        "/motor/temperature": (sensor, {**TEMPERATURE_FIELDS, "temperature": 77.7}),
    }
    try:

        def matched() -> bool:
            stats = heard.source.topic_stats()
            for writer, fields in writes.values():
                robot.write(writer, fields)
            return all(
                stats[topic]["qos"] == "reliable, volatile" and received[topic] > 0
                for topic in writes
            )

        wait_for(matched, 30, "both topics, read reliably", every=0.2)
        before = {topic: received[topic] for topic in writes}
        sent = {
            topic: robot.write_at(writer, fields, hz=50, seconds=1.5)
            for topic, (writer, fields) in burst.items()
        }
        assert all(count >= 70 for count in sent.values()), sent
        if recording:  # delivered as they come: the last ones may still be on their way

            def all_delivered() -> bool:
                return all(received[t] - before[t] >= sent[t] for t in writes)

            wait_for(all_delivered, 30, f"the {sent} messages")
        # (a warm-up message still on its way when ``before`` was read counts too)
        delivered = {topic: received[topic] - before[topic] for topic in writes}
        stats = heard.source.topic_stats()
        if recording:  # what the window holds: a mark records it
            assert heard.pipeline.recorder.mark("count").outcome == "opened"
            parts = wait_for(lambda: incident_parts(heard.events), 30, "the mark's incident")
    finally:
        heard.close()
        robot.close()
    assert {topic: stats[topic]["qos_incompatible"] for topic in writes} == {
        "/odom": 0,
        "/motor/temperature": 0,
    }
    if recording:
        assert all(delivered[t] >= sent[t] for t in writes), (delivered, sent)
        samples = [
            (topic, sample)
            for part in parts
            for topic, topic_samples in part["incident"]["samples"].items()
            for sample in topic_samples
        ]
        in_window = {
            "/odom": sum(
                s.get("local", {}).get("x_m") == 777.0 for t, s in samples if t == "/odom"
            ),
            "/motor/temperature": sum(
                s.get("temperature") == 77.7 for t, s in samples if t == "/motor/temperature"
            ),
        }
        assert in_window == sent  # every message, once
    else:
        # 1.5 s of writing at 50 Hz each, 3 s in all: at most a take a tick (5 Hz)
        # while each was written, and the extra topic's once a second
        assert 1 <= delivered["/odom"] <= 1.5 * 5 + 2, delivered
        assert 1 <= delivered["/motor/temperature"] <= 1.5 * 1 + 2, delivered


def test_the_window_topics_follow_best_effort_writers(tmp_path: Path) -> None:
    """A window topic delivered on every message is still listened to as a state
    stream before its writer is known (best effort: any writer matches) and then with
    what its writer offers, never reliably as the every-message topics are."""
    ros = private_loopback_domain()
    robot = DdsRobot(ros, tmp_path / "robot.log")
    heard = started(robot, ros, INCIDENT_RECORDING="true", INCIDENT_TOPICS="/odom,/imu/data")
    try:
        silent = heard.source.topic_stats()["/odom"]
        odom = robot.writer("/odom", *KNOWN["/odom"][:2])
        assert KNOWN["/odom"][1] == "best_effort"

        def heard_odom() -> dict[str, Any] | None:
            robot.write(odom, KNOWN["/odom"][2])
            stats = heard.source.topic_stats()
            seen = heard.dispatcher.received["/odom"] > 0 and stats["/odom"]["publishers"]
            return stats if seen else None

        stats = wait_for(heard_odom, 30, "the best-effort odometry and its writer", every=0.1)
    finally:
        heard.close()
        robot.close()
    assert silent == {"publishers": 0, "qos": "best effort, volatile", "qos_incompatible": 0}
    assert stats["/odom"] == {
        "publishers": 1,
        "qos": "best effort, volatile",
        "qos_incompatible": 0,
    }
    assert stats["/imu/data"]["qos"] == "best effort, volatile"
