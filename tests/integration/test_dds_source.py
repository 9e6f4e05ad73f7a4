"""The ROS-free DDS input against a real Cyclone DDS publisher in another process, on a
private domain confined to loopback; and the IDL types against the Jazzy definitions."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import threading
import typing
from pathlib import Path

import pytest

pytest.importorskip("cyclonedds", reason="the DDS input needs cyclonedds (pip install .[dds])")

from cyclonedds.idl import IdlStruct

from phytrace_edge.builder.assemble import DOMAINS
from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.sampler import Sampler
from phytrace_edge.config import load_settings
from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.sources import dds_types
from phytrace_edge.ingest.sources.base import Feed
from phytrace_edge.ingest.sources.dds import DdsSource, domain_settings
from phytrace_edge.runtime import wiring
from phytrace_edge.udm.schema import find_violation
from tests.processes import python_env, wait_for
from tests.unit.test_generic import KNOWN

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


def topic_events(events: list[dict]) -> dict[str, dict]:
    """The latest telemetry.topic event of each topic."""
    return {e["topic"]: e for e in events if e["event_type"] == "telemetry.topic"}


def test_events_from_a_real_dds_publisher(monkeypatch: pytest.MonkeyPatch) -> None:
    domain = str(random.Random(os.getpid()).randint(100, 200))  # private to this test
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    publisher = subprocess.Popen(
        [sys.executable, PUBLISHER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=python_env(ROS_DOMAIN_ID=domain, ROS_LOCALHOST_ONLY="1"),
    )
    events: list[dict] = []
    source = None
    stop = threading.Event()
    try:
        assert publisher.stdout.readline().strip() == "ready"
        extras = (
            "/motor/temperature type=sensor_msgs/msg/Temperature rate_hz=50; "
            "/tf type=tf2_msgs/msg/TFMessage rate_hz=50; "
            "/cells type=std_msgs/msg/Float32MultiArray rate_hz=50; "
            "/camera type=sensor_msgs/msg/CompressedImage rate_hz=50; "
            "/no/type; /vendor type=acme_msgs/msg/Unknown"
        )
        settings = load_settings(
            env={"SAMPLE_RATE_HZ": "10", "BRIDGE_INPUT": "dds", "TOPICS_EXTRA": extras}
        ).settings
        source = DdsSource(wiring.source_options(settings, os.environ))
        builder = UDMBuilder(wiring.builder_options(settings), field_types=source.field_types)
        dispatcher = Dispatcher(builder.add_reading, builder.add_message)
        sampler = Sampler(
            builder, lambda built: events.append(built.event), 10, before_tick=source.before_tick
        )
        source.start(Feed(dispatcher.on_message, sampler.tick, sampler.period_s))
        threading.Thread(target=sampler.run, args=(stop,), daemon=True).start()
        wanted = set(DOMAINS)
        event = wait_for(
            lambda: next((e for e in reversed(events) if wanted <= set(e)), None),
            60,
            "an event with every domain",
        )
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
        stop.set()
        if source is not None:
            source.stop()
        if publisher.poll() is None:
            publisher.stdin.close()
            publisher.wait(timeout=20)
    assert find_violation(event) is None
    assert event["location"]["local"] == pytest.approx(
        {"coordinate_frame": "odom", "x_m": 12.34, "y_m": 5.67, "z_m": 0.0, "yaw_deg": 45.2}
    )
    assert event["location"]["latitude"] == 41.8781
    assert event["motion"]["linear_velocity"]["x_mps"] == 0.85
    assert event["motion"]["commanded_velocity"] == {
        "linear_x_mps": 1.0,
        "linear_y_mps": 0.0,
        "angular_z_rps": -0.5,
    }
    battery = event["power"]["battery"]
    assert battery["state_of_charge_pct"] == pytest.approx(82.5)
    assert battery["voltage_v"] == pytest.approx(24.1, rel=1e-6)
    assert "charge_ah" not in battery  # NaN on the wire
    lidar = event["perception"]["lidar"][0]
    assert (lidar["num_points"], lidar["valid_points"]) == (5, 2)
    assert lidar["closest_range_m"] == pytest.approx(0.5)
    assert event["perception"]["imu"]["orientation_deg"]["yaw"] == pytest.approx(30.0)
    errors = event["operational"]["errors"]
    assert [(e["name"], e["level"]) for e in errors] == [("motor", "error")]
    assert event["navigation"]["goal"]["x_m"] == 45.0
    assert [j["name"] for j in event["actuators"]["joints"]] == ["left_wheel", "right_wheel"]
    assert event["payload"]["delivery_state"] == "in_transit"
    assert event["location"]["sources"][0]["stamp"] == "2025-11-13T02:13:20.500Z"
    received = dispatcher.received
    assert received["/odom"] > 0 and received["/battery_state"] > 0  # best effort and reliable
    # TOPICS_EXTRA through Cyclone DDS: the same JSON as rclpy and rosbags give
    by_topic = topic_events(events)
    for make, expected in KNOWN:
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
