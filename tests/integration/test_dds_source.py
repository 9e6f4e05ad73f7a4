"""The ROS-free DDS input against a real Cyclone DDS publisher in another process, on a
private domain confined to loopback; and the IDL types against the Jazzy definitions."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import typing
from collections.abc import Callable
from pathlib import Path

import pytest

pytest.importorskip("cyclonedds", reason="the DDS input needs cyclonedds (pip install .[dds])")

from cyclonedds.idl import IdlStruct

from phytrace_edge.config import load_settings
from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.sources import dds_types
from phytrace_edge.ingest.sources.dds import DdsSource, domain_config
from phytrace_edge.ingest.sources.dds_env import domain_settings
from phytrace_edge.runtime import options, wiring
from phytrace_edge.udm.schema import find_violation
from tests.processes import python_env, wait_for
from tests.ros.known import KNOWN, carries_every_known_value, check_known_event
from tests.ros.rig import Robot, private_domain, rclpy_missing, ros_env
from tests.unit.test_generic import KNOWN as KNOWN_EXTRA

PUBLISHER = str(Path(__file__).with_name("dds_publisher.py"))


def describe_idl(hint: typing.Any) -> tuple:
    """An IDL field type as (kind, ...), comparable with rosbags' field definitions."""
    if hint is str:
        return ("base", "string")
    if hint is bool:
        return ("base", "bool")
    if isinstance(hint, type) and issubclass(hint, IdlStruct):
        package, _, _, name = hint.__idl_typename__.split("::")
        return ("name", f"{package}/msg/{name.rstrip('_')}")
    meta = typing.get_args(hint)[1]
    if isinstance(meta, str):
        return ("base", meta)
    kind = type(meta).__name__
    inner = describe_idl(meta.subtype)
    return ("array", inner, meta.length) if kind == "array" else ("sequence", inner)


def describe_rosbags(node: tuple) -> tuple:
    kind, detail = node
    if kind.name == "BASE":
        return ("base", {"byte": "byte", "octet": "byte"}.get(detail[0], detail[0]))
    if kind.name == "NAME":
        return ("name", detail)
    if kind.name == "ARRAY":
        return ("array", describe_rosbags(detail[0]), detail[1])
    return ("sequence", describe_rosbags(detail[0]))


def all_idl_types() -> list[type]:
    return [
        v
        for v in vars(dds_types).values()
        if isinstance(v, type) and issubclass(v, IdlStruct) and v is not IdlStruct
    ]


@pytest.mark.parametrize("idl", all_idl_types(), ids=lambda t: t.__name__)
def test_idl_types_match_the_jazzy_definitions(idl: type) -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    package, _, _, name = idl.__idl_typename__.split("::")
    ros_fields = store.fielddefs[f"{package}/msg/{name.rstrip('_')}"][1]
    hints = typing.get_type_hints(idl, include_extras=True)
    assert list(hints) == [field for field, _ in ros_fields]
    for field, node in ros_fields:
        assert describe_idl(hints[field]) == describe_rosbags(node), field


def test_ros_environment_picks_the_domain_and_loopback() -> None:
    assert domain_settings({}) == (0, False)
    assert domain_settings({"ROS_DOMAIN_ID": "7", "ROS_LOCALHOST_ONLY": "1"}) == (7, True)
    assert domain_settings({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})[1] is True
    with pytest.raises(ConfigError, match="ROS_DOMAIN_ID"):
        domain_settings({"ROS_DOMAIN_ID": "seven"})


def test_the_domain_config_hears_fast_dds_and_keeps_the_users_own() -> None:
    anywhere, loopback = domain_config(localhost_only=False), domain_config(localhost_only=True)
    assert "<IgnoreTypeInformation>1.15</IgnoreTypeInformation>" in anywhere
    assert "127.0.0.1" not in anywhere and "<NetworkInterface address='127.0.0.1'/>" in loopback
    merged = domain_config(False, "file:///etc/cyclonedds.xml")
    assert merged == "file:///etc/cyclonedds.xml," + anywhere  # Cyclone merges the list


def topic_events(events: list[dict]) -> dict[str, dict]:
    """The latest telemetry.topic event of each topic."""
    return {e["topic"]: e for e in events if e["event_type"] == "telemetry.topic"}


class DdsInput:
    """The dds input, its builder, sample tick and graph checks (the input's own loop),
    in this process; events in memory."""

    def __init__(self, env: dict[str, str], extras: str = "", **settings_env: str) -> None:
        settings = load_settings(
            env={
                "SAMPLE_RATE_HZ": "10",
                "BRIDGE_INPUT": "dds",
                "TOPICS_EXTRA": extras,
                **settings_env,
            }
        ).settings
        self.events: list[dict] = []
        self.source = DdsSource(options.source_options(settings, env))
        self.pipeline = wiring.build_pipeline(
            settings, self.source, lambda built: self.events.append(built.event)
        )
        self.dispatcher = self.pipeline.dispatcher
        self._stop = threading.Event()
        self.pipeline.open()
        self._loops = [
            threading.Thread(target=loop, args=(self._stop, lambda: None))
            for loop in (self.pipeline.tick, self.pipeline.ingest)
        ]
        for loop in self._loops:
            loop.start()

    def event_with_every_domain(self, during: Callable[[], None] = lambda: None) -> dict:
        def found() -> dict | None:
            during()
            return next((e for e in reversed(self.events) if carries_every_known_value(e)), None)

        return wait_for(found, 60, "an event with every known value", every=0.2)

    def close(self) -> None:
        self._stop.set()
        for loop in self._loops:
            loop.join(10)
        self.source.stop()


def private_loopback_domain() -> dict[str, str]:
    return {"ROS_DOMAIN_ID": str(private_domain()), "ROS_LOCALHOST_ONLY": "1"}


def test_events_from_a_real_dds_publisher() -> None:
    ros = private_loopback_domain()
    publisher = subprocess.Popen(
        [sys.executable, PUBLISHER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=python_env(**ros),
    )
    heard = None
    try:
        assert publisher.stdout.readline().strip() == "ready"
        heard = DdsInput(
            ros,
            "/motor/temperature type=sensor_msgs/msg/Temperature rate_hz=50; "
            "/tf type=tf2_msgs/msg/TFMessage rate_hz=50; "
            "/cells type=std_msgs/msg/Float32MultiArray rate_hz=50; "
            "/camera type=sensor_msgs/msg/CompressedImage rate_hz=50; "
            "/no/type; /vendor type=acme_msgs/msg/Unknown",
        )
        events, source, dispatcher = heard.events, heard.source, heard.dispatcher
        event = heard.event_with_every_domain()
        wait_for(
            lambda: (
                {"/motor/temperature", "/tf", "/cells", "/camera"} <= topic_events(events).keys()
                and any(e["event_type"] == "log.record" for e in events)
            ),
            60,
            "the extra topics and the log record",
        )
        stats = source.topic_stats()
        # the robot goes away: its writers unregister their instances, samples that
        # carry no data, which must not reach the handlers
        rejected_before = dict(dispatcher.rejected)
        publisher.stdin.close()
        publisher.wait(timeout=20)
        wait_for(
            lambda: source.topic_stats().get("/delivery/status", {}).get("without_data"),
            30,
            "the writers' unregistration",
        )
        assert dict(dispatcher.rejected) == rejected_before == {}
    finally:
        if heard is not None:
            heard.close()
        if publisher.poll() is None:
            publisher.stdin.close()
            publisher.wait(timeout=20)
    assert find_violation(event) is None
    check_known_event(event)
    received = dispatcher.received
    assert received["/odom"] > 0 and received["/battery_state"] > 0  # best effort and reliable
    # TOPICS_EXTRA through Cyclone DDS: the same JSON as rclpy and rosbags give
    by_topic = topic_events(events)
    for make, expected in KNOWN_EXTRA:
        name = make()._type
        topic = next(t for t, e in by_topic.items() if e["type"] == name)
        assert by_topic[topic]["data"] == expected, topic
        assert find_violation(by_topic[topic]) is None
    assert "dds input needs its type" in stats["/no/type"]["skipped"]
    assert "acme_msgs/msg/Unknown" in stats["/vendor"]["skipped"]
    log = next(e for e in events if e["event_type"] == "log.record")
    assert (log["level"], log["logger"], log["message"], log["line"]) == (
        "error",
        "acme.drive",
        "overcurrent",
        7,
    )


def test_events_from_a_fast_dds_publisher(tmp_path: Path) -> None:
    """ROS 2's default middleware: a real rclpy robot on rmw_fastrtps_cpp (the Kilted
    wheels) publishes the ten topics; the dds input, on Cyclone DDS, hears every value
    (Fast DDS's type information would stop Cyclone from matching: see the input's
    ``domain_config``)."""
    if missing := rclpy_missing():
        if os.environ.get("CI"):
            pytest.fail(missing)
        pytest.skip(missing)
    ros = ros_env(private_domain(), tmp_path / "ros-logs")
    robot = Robot("kilted", ros, tmp_path / "robot.log")
    heard = None
    try:
        publishers = {t: robot.publisher(t, kind, qos) for t, (kind, qos, _) in KNOWN.items()}

        def publish_all() -> None:  # as a robot does, again and again
            for topic, (_, _, fields) in KNOWN.items():
                robot.publish(publishers[topic], fields)

        heard = DdsInput(ros)
        event = heard.event_with_every_domain(during=publish_all)
    finally:
        if heard is not None:
            heard.close()
        robot.close()
    assert find_violation(event) is None
    check_known_event(event)
    assert heard.dispatcher.received["/odom"] > 0 and heard.dispatcher.received["/diagnostics"] > 0
