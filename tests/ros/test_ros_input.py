"""The ``ros`` input, end to end, on real rclpy and on the mock with the same bodies.

A robot node publishes with the QoS real drivers use, the bridge runs as
``phytrace-edge run --input ros``, and the test reads what reached the stub, what
``status`` says, what the bridge's node answers to a parameter client, and how the
bridge exits. Where the two graphs disagree, the mock is wrong.
"""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from phytrace_edge.builder.assemble import DOMAINS
from tests.processes import wait_for
from tests.ros.known import KNOWN, check_known_event
from tests.ros.rig import Rig

ERROR = {"level": 2, "name": "motor", "message": "overcurrent", "hardware_id": "mc"}


def publish_known(rig: Rig, topics: dict[str, tuple[str, str, dict]]) -> dict[str, int]:
    publishers = {t: rig.publisher(t, type_name, qos) for t, (type_name, qos, _) in topics.items()}
    for topic, (_, _, fields) in topics.items():
        rig.publish(publishers[topic], fields)
    return publishers


def has_every_domain(event: dict) -> bool:
    return set(DOMAINS) <= set(event)


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
        return next((e for e in reversed(rig.events()) if has_every_domain(e)), None)

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
