"""The ``ros`` input, end to end, on real rclpy and on the mock with the same bodies.

A robot node publishes with the QoS real drivers use, the bridge runs as
``phytrace-edge run --input ros``, and the test reads what reached the stub, what
``status`` says, what the bridge's node answers to a parameter client, and how the
bridge exits. Where the two graphs disagree, the mock is wrong.
"""

from __future__ import annotations

import copy
import signal
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest

from tests.processes import wait_for
from tests.ros.known import KNOWN, carries_every_known_value, check_known_event
from tests.ros.rig import Rig

ERROR = {"level": 2, "name": "motor", "message": "overcurrent", "hardware_id": "mc"}


def publish_known(rig: Rig, topics: dict[str, tuple[str, str, dict]]) -> dict[str, int]:
    publishers = {t: rig.publisher(t, type_name, qos) for t, (type_name, qos, _) in topics.items()}
    for topic, (_, _, fields) in topics.items():
        rig.publish(publishers[topic], fields)
    return publishers


def test_all_ten_topics_with_known_values(rig: Rig) -> None:
    """Best effort (odometry, scan, IMU, GPS, joints), reliable (battery, command,
    diagnostics, delivery) and a transient-local goal published before the bridge
    started: every value arrives, compared field by field."""
    goal = {"/goal_pose": KNOWN["/goal_pose"]}
    publish_known(rig, goal)  # latched: the bridge must still get it
    rig.start_bridge()
    others = {t: v for t, v in KNOWN.items() if t not in goal}
    publishers = {t: rig.publisher(t, type_name, qos) for t, (type_name, qos, _) in others.items()}

    def republish_and_look() -> dict | None:
        # publishers keep publishing, as a robot does, until every domain is in one event
        for topic, (_, _, fields) in others.items():
            rig.publish(publishers[topic], fields)
        return next((e for e in reversed(rig.events()) if carries_every_known_value(e)), None)

    event = wait_for(republish_and_look, 60, "an event with every domain", every=0.3)
    check_known_event(event)
    matched = {
        "/scan": "best effort, volatile",
        "/battery_state": "reliable, volatile",
        "/goal_pose": "reliable, transient local",
    }

    def subscribed_as_offered() -> bool:  # status is the heartbeat's: seconds behind
        topics = rig.status_json().get("topics", {})
        return {t: topics.get(t, {}).get("qos") for t in matched} == matched

    wait_for(subscribed_as_offered, 30, f"status to show {matched}", every=0.5)


def test_a_topic_that_appears_late_is_picked_up(rig: Rig) -> None:
    battery = rig.publisher("/battery_state", *KNOWN["/battery_state"][:2])
    rig.start_bridge()
    rig.publish_until(battery, KNOWN["/battery_state"][2], lambda e: "power" in e, "the battery")
    gps = rig.publisher("/gps/fix", *KNOWN["/gps/fix"][:2])
    event = rig.publish_until(
        gps, KNOWN["/gps/fix"][2], lambda e: "latitude" in e.get("location", {}), "the late fix"
    )
    assert event["location"]["latitude"] == 41.8781


def test_a_one_shot_message_right_after_its_publisher_appears(rig: Rig) -> None:
    """A diagnostics ERROR published once, as soon as its new publisher has matched the
    bridge, before the bridge looks at the graph again: it is heard."""
    rig.start_bridge()
    rig.wait_running()
    diagnostics = rig.publisher("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "reliable")
    matched = rig.publish(diagnostics, {"status": [ERROR]}, matched_within_s=20)
    assert matched == 1
    event = rig.wait_event(lambda e: e.get("operational", {}).get("errors"), "the one-shot ERROR")
    assert [(e["name"], e["level"]) for e in event["operational"]["errors"]] == [("motor", "error")]


def test_rosout_warn_and_above_become_log_records(rig: Rig) -> None:
    rig.start_bridge()
    rig.wait_running()
    for level in ("info", "warning", "error"):
        rig.command("log", level=level, text=f"a {level} from the robot")
    rig.wait_event(lambda e: e["level"] == "error", "the ERROR log record", "log.record")
    records = {(r["level"], r["message"]) for r in rig.events("log.record")}
    assert records == {("warn", "a warning from the robot"), ("error", "a error from the robot")}
    assert {r["logger"] for r in rig.events("log.record")} == {"robot"}

    def rosout_in_status() -> dict[str, Any] | None:  # the heartbeat's: seconds behind
        rosout = rig.status_json().get("topics", {}).get("/rosout", {})
        heard = rosout.get("rate_hz", 0) > 0 and rosout.get("last_seen_age_s") is not None
        return rosout if heard else None

    # it showed 0.0 Hz and no age after records had arrived
    rosout = wait_for(rosout_in_status, 30, "/rosout's rate and age in status", every=0.5)
    assert rosout["received"] >= 3 and rosout["records"] == 2


def test_an_extra_topic_of_an_installed_type(rig: Rig) -> None:
    rig.start_bridge(TOPICS_EXTRA="/motor/temperature rate_hz=5")
    sensor = rig.publisher("/motor/temperature", "sensor_msgs/msg/Temperature", "reliable")
    fields = {"header": {"frame_id": "motor"}, "temperature": 41.5, "variance": 0.25}

    def heard() -> dict | None:
        rig.publish(sensor, fields)
        return next(iter(rig.events("telemetry.topic")), None)

    event = wait_for(heard, 60, "the extra topic's event", every=0.3)
    assert event["topic"] == "/motor/temperature"
    assert event["type"] == "sensor_msgs/msg/Temperature"
    assert event["data"]["temperature"] == 41.5 and event["data"]["variance"] == 0.25
    assert event["data"]["header"]["frame_id"] == "motor"


def test_qos_problems_are_shown_in_status(rig: Rig) -> None:
    """A reliable subscription forced on a best-effort lidar gets nothing: status says
    so, per topic, in text and JSON."""
    scan = rig.publisher("/scan", "sensor_msgs/msg/LaserScan", "best_effort")
    rig.start_bridge("-p", "topic_qos:=/scan=reliable")
    rig.wait_running()

    def counted() -> bool:
        rig.publish(scan, KNOWN["/scan"][2])
        return rig.status_json().get("topics", {}).get("/scan", {}).get("qos_incompatible", 0) >= 1

    wait_for(counted, 60, "the incompatible publisher in status", every=0.5)
    _, text = rig.status()
    assert "QoS incompatible with 1 publisher(s)" in text
    assert not any("perception" in e for e in rig.events())


def test_every_node_of_the_bridge_answers_its_parameter_services(rig: Rig) -> None:
    """What ``ros2 param list`` does: ask every node in the graph. Each of the bridge's
    nodes answers within 2 s (a node that no executor spins never would)."""
    rig.start_bridge()
    rig.wait_running()
    nodes = wait_for(
        lambda: [n for n in rig.command("nodes") if n != "/robot"] or None, 30, "the bridge's node"
    )
    assert nodes == ["/phytrace_edge"]
    for node in nodes:
        names = rig.parameters(node, "list", answer_s=2.0)
        assert names is not None, f"{node} did not answer list_parameters within 2 s"
        assert "source_id" in names


def test_parameters_from_a_params_file_and_p_are_read_only_and_never_the_key(
    rig: Rig, tmp_path: Path
) -> None:
    params = tmp_path / "bridge.params.yaml"
    params.write_text(
        "/phytrace_edge:\n"
        "  ros__parameters:\n"
        "    source_id: file-robot\n"
        "    sample_rate_hz: 2.0\n"
        "    fleet_id: from-file\n"
        "    phycloud_api_key: phk_in_a_params_file\n"
    )
    odom = rig.publisher("/odom", *KNOWN["/odom"][:2])
    rig.start_bridge(
        "--params-file", str(params), "-p", "sample_rate_hz:=10.0", "-p", "fleet_id:=from-p",
        SOURCE_ID="", SAMPLE_RATE_HZ="", FLEET_ID="from-env",
    )  # fmt: skip
    event = rig.publish_until(odom, KNOWN["/odom"][2], lambda e: "location" in e, "odometry")
    assert event["source_id"] == "file-robot"
    names = ["source_id", "sample_rate_hz", "fleet_id"]
    values = rig.parameters("/phytrace_edge", "get", names=names)
    assert values == {
        "source_id": "file-robot",  # the file
        "sample_rate_hz": 10.0,  # -p after the file wins
        "fleet_id": "from-env",  # the environment outranks ROS parameters
    }
    # never a parameter: rclpy answers nothing for a name that is not declared
    assert rig.parameters("/phytrace_edge", "get", names=["phycloud_api_key"]) == {}
    described = rig.parameters("/phytrace_edge", "describe", names=names)
    assert all(d["read_only"] for d in described.values()) and len(described) == 3
    assert "robot" in described["source_id"]["description"]
    refused = rig.parameters("/phytrace_edge", "set", values={"source_id": "renamed"})
    assert refused[0]["successful"] is False and "read-only" in refused[0]["reason"]
    assert "phycloud_api_key" not in rig.parameters("/phytrace_edge", "list")
    assert "phk_in_a_params_file" not in rig.bridge_log.read_text()


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_the_bridge_cleanly(rig: Rig, signum: int) -> None:
    odom = rig.publisher("/odom", *KNOWN["/odom"][:2])
    rig.start_bridge()
    rig.publish_until(odom, KNOWN["/odom"][2], lambda e: "location" in e, "the odometry")
    code, log = rig.stop_bridge(signum)
    assert code == 0, log
    assert "Traceback" not in log and "Exception" not in log
    assert "event(s) left in the queue" in log


def test_a_taken_message_comes_with_its_message_info(rig: Rig) -> None:
    """What the bridge reads the age of a taken message from: rclpy's ``take_message``
    gives (message, message info) with the writing and reception stamps on the wall
    clock (the mock's take gave an empty dict). On Humble, rclpy 3.3 gives no sequence
    number, and Humble's rmw_cyclonedds_cpp no reception stamp (0: the bridge takes the
    writer's)."""
    publisher = rig.publisher("/odom", "nav_msgs/msg/Odometry", "reliable")
    info = rig.command("message_info", id=publisher, fields=KNOWN["/odom"][2])
    kinds = info["kinds"]
    assert (kinds["source_timestamp"], kinds["received_timestamp"]) == ("int", "int")
    if rig.flavour == "humble":
        assert "publication_sequence_number" not in kinds
    else:
        assert kinds["publication_sequence_number"] == "int"
    assert info["written_then_received"] is True
    cyclone = rig.env["RMW_IMPLEMENTATION"] == "rmw_cyclonedds_cpp"
    assert info["reception_stamped"] is not (rig.flavour == "humble" and cyclone)


def captured_s(event: dict[str, Any]) -> float:
    return datetime.fromisoformat(event["captured_at"].replace("Z", "+00:00")).timestamp()


def test_a_message_taken_at_the_tick_is_as_old_as_its_reception(rig: Rig) -> None:
    """Odometry is taken at the sample tick (1 Hz here), up to a second after it was
    received: the first event with each new position says how long ago (the
    middleware's reception stamp), so ``captured_at - age_s`` is when it was published
    (it was the tick's own time: ``age_s`` 0.0)."""
    type_name, _, fields = KNOWN["/odom"]
    odom = rig.publisher("/odom", type_name, "reliable")  # one message each: none lost
    rig.start_bridge(SAMPLE_RATE_HZ="1")
    rig.publish_until(odom, fields, lambda e: "location" in e, "the odometry")
    wait_for(
        lambda: (
            rig.status_json().get("topics", {}).get("/odom", {}).get("qos") == "reliable, volatile"
        ),
        30,
        "the subscription to match the reliable publisher",
        every=0.5,
    )
    for x in (21.5, 22.5, 23.5, 24.5):
        moved = copy.deepcopy(fields)
        moved["pose"]["pose"]["position"]["x"] = x
        before = time.time()
        rig.publish(odom, moved)
        after = time.time()

        def taken(e: dict[str, Any], x: float = x) -> bool:
            return e.get("location", {}).get("local", {}).get("x_m") == x

        rig.wait_event(taken, f"the odometry at x={x}")
        first = min((e for e in rig.events() if taken(e)), key=captured_s)
        [source] = [s for s in first["location"]["sources"] if s["topic"] == "/odom"]
        received_at = captured_s(first) - source["age_s"]
        assert before - 0.003 <= received_at <= after + 0.1, (before, received_at, after)


def test_an_extra_topic_is_taken_at_its_own_rate(rig: Rig) -> None:
    """An extra topic at rate_hz=1, published at 20 Hz into the 5 Hz sample tick: taken
    (deserialised) only when due, so each message taken is one event; it was taken at
    every tick, five messages deserialised for each one sent."""
    rig.start_bridge(TOPICS_EXTRA="/motor/temperature rate_hz=1")
    sensor = rig.publisher("/motor/temperature", "sensor_msgs/msg/Temperature", "reliable")
    fields = {"header": {"frame_id": "motor"}, "temperature": 41.5, "variance": 0.25}

    def figures() -> dict[str, Any]:
        return rig.status_json().get("topics", {}).get("/motor/temperature", {})

    def matched() -> dict[str, Any] | None:  # the reliable subscription, and a first event
        rig.publish(sensor, fields)
        now = figures()
        return now if now.get("qos") == "reliable, volatile" and now.get("events") else None

    before = wait_for(matched, 60, "the extra topic subscribed and sent", every=0.3)
    assert rig.publish_at(sensor, fields, hz=20, seconds=4) >= 60

    def counted() -> dict[str, Any] | None:
        now = figures()
        return now if now.get("events", 0) >= before["events"] + 3 else None

    after = wait_for(counted, 30, "status to count the events", every=0.5)
    taken = after["received"] - before["received"]
    sent = after["events"] - before["events"]
    # each figure of a heartbeat is read a moment apart: one message either way
    assert 3 <= sent <= 6 and abs(taken - sent) <= 2, (before, after)
