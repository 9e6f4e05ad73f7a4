"""The rclpy source, run on the mock rclpy layer (which models QoS compatibility):
late topics, QoS matching and re-matching, latched topics, overrides, remapping,
namespaces and ROS parameters."""

from __future__ import annotations

import math
from datetime import datetime

import pytest

from phytrace_edge.cli import main
from phytrace_edge.config import load_settings
from phytrace_edge.ingest.sources.ros import RosSource
from phytrace_edge.ingest.sources.ros_graph import GRAPH_CHECK_S, NodeClock
from phytrace_edge.runtime import options, wiring
from phytrace_edge.sim import mock_ros
from phytrace_edge.sim.mock_ros import as_rclpy
from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.sim.mock_ros.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


class Graph:
    """A virtual-time ROS graph with the bridge's subscriptions and sample tick on it."""

    def __init__(self, **env: str) -> None:
        self.context = mock_ros.Context(virtual_time=True)
        modules = as_rclpy.modules(self.context)
        modules["rclpy"].init()
        self.events: list[dict] = []
        settings = load_settings(env={"BRIDGE_INPUT": "ros", **env}).settings
        # the ros input itself, over the mock's modules (the simulator's way)
        self.source = RosSource(options.source_options(settings, {}), modules.__getitem__)
        self.api = self.source.api
        self.source.clock = NodeClock(self.api)  # virtual time, as the simulator's source
        self.robot = self.api.create_node("robot")
        pipeline = wiring.build_pipeline(
            settings, self.source, lambda b: self.events.append(b.event)
        )
        pipeline.open()
        self.dispatcher = pipeline.dispatcher
        self.builder = pipeline.builder
        self.executor = self.source.executor
        self.executor.add_node(self.robot)
        # in virtual time the sample tick is a timer of the bridge's node
        steady = self.api.clock("steady")
        self.source.node.create_timer(
            pipeline.sampler.period_s, pipeline.sampler.tick, clock=steady
        )

    def run(self, seconds: float) -> None:
        end = self.context.time_source.steady_ns() + int(seconds * 1e9)
        while self.context.time_source.steady_ns() < end:
            self.executor.spin_once(timeout_sec=0.05)

    def run_until(self, steady_s: float) -> None:
        """Spin until exactly ``steady_s`` of virtual time (timers due before fire)."""
        end = round(steady_s * 1e9)
        while (now := self.context.time_source.steady_ns()) < end:
            self.executor.spin_once(timeout_sec=(end - now) / 1e9)

    def received(self, topic: str) -> int:
        return self.dispatcher.received[topic]

    @property
    def subscriber(self):
        return self.source.subscriber

    def subscription(self, topic: str):
        return self.subscriber.subscribed.get(topic)

    def close(self) -> None:
        mock_ros.shutdown(context=self.context)


@pytest.fixture
def graph():
    graphs: list[Graph] = []

    def make(**env: str) -> Graph:
        graphs.append(Graph(**env))
        return graphs[-1]

    yield make
    for g in graphs:
        g.close()


def odom(x: float) -> m.Odometry:
    msg = m.Odometry()
    msg.pose.pose.position = m.Point(x=x, y=0.0, z=0.0)
    return msg


def test_a_message_published_before_the_next_graph_check_is_not_lost(graph) -> None:
    """Every topic is subscribed from the start, so a one-shot ERROR published a second
    after its publisher appeared, before the bridge looked at the graph again, is heard
    (it was lost in 4 of 4 runs on real rclpy when subscriptions waited for the graph).
    Diagnostics are listened to as their publishers offer them, reliable and volatile,
    so the graph check finds nothing to change."""
    g = graph()
    first = g.subscription("/diagnostics").handle
    choice = g.subscription("/diagnostics").qos
    assert (choice.reliable, choice.transient_local) == (True, False)
    g.run(0.5)
    publisher = g.robot.create_publisher(m.DiagnosticArray, "/diagnostics", RELIABLE)
    g.run(1.0)  # discovered, but the next graph check is later
    error = m.DiagnosticStatus(level=b"\x02", name="motor", message="overcurrent")
    publisher.publish(m.DiagnosticArray(status=[error]))
    g.run(0.3)
    assert g.received("/diagnostics") == 1
    errors = [e for ev in g.events for e in ev.get("operational", {}).get("errors", [])]
    assert [(e["name"], e["level"]) for e in errors][:1] == [("motor", "error")]
    g.run(GRAPH_CHECK_S)
    assert g.subscription("/diagnostics").handle is first  # matched already: not re-created


def test_state_streams_listen_best_effort_before_a_publisher_is_seen(graph) -> None:
    """A sensor's driver publishes best effort: before the bridge has seen one, it
    listens best effort, which matches any publisher."""
    g = graph()
    choice = g.subscription("/scan").qos
    assert (choice.reliable, choice.transient_local) == (False, False)
    scan = g.robot.create_publisher(m.LaserScan, "/scan", BEST_EFFORT)
    g.run(0.5)
    scan.publish(m.LaserScan(range_min=0.1, range_max=10.0, ranges=[2.0]))
    g.run(0.5)
    assert g.received("/scan") == 1


def test_a_best_effort_sensor_is_heard(graph) -> None:
    g = graph()
    g.robot.create_publisher(m.LaserScan, "/scan", BEST_EFFORT).publish(m.LaserScan())
    g.run(GRAPH_CHECK_S + 0.1)
    choice = g.subscription("/scan").qos
    assert (choice.reliable, choice.transient_local) == (False, False)


def test_a_new_incompatible_publisher_gets_the_subscription_recreated(graph) -> None:
    g = graph()
    reliable = g.robot.create_publisher(m.DiagnosticArray, "/diagnostics", RELIABLE)
    g.run(GRAPH_CHECK_S + 0.1)
    first = g.subscription("/diagnostics").handle
    choice = g.subscription("/diagnostics").qos
    assert choice.reliable
    best_effort = g.robot.create_publisher(m.DiagnosticArray, "/diagnostics", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    second = g.subscription("/diagnostics").handle
    choice = g.subscription("/diagnostics").qos
    assert second is not first and not choice.reliable
    reliable.publish(m.DiagnosticArray())
    best_effort.publish(m.DiagnosticArray())
    g.run(0.5)
    assert g.received("/diagnostics") == 2  # both publishers are heard


def test_a_latched_goal_published_before_the_bridge_is_received(graph) -> None:
    g = graph()
    publisher = g.robot.create_publisher(m.PoseStamped, "/goal_pose", LATCHED)
    goal = m.PoseStamped()
    goal.pose.position = m.Point(x=45.0, y=22.0, z=0.0)
    publisher.publish(goal)
    g.run(GRAPH_CHECK_S + 0.5)
    choice = g.subscription("/goal_pose").qos
    assert choice.transient_local and choice.reliable
    assert g.events[-1]["navigation"]["goal"]["x_m"] == 45.0


def test_an_override_that_cannot_match_is_counted(graph) -> None:
    g = graph(TOPIC_QOS="/scan=reliable")
    publisher = g.robot.create_publisher(m.LaserScan, "/scan", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    publisher.publish(m.LaserScan())
    g.run(0.5)
    assert g.received("/scan") == 0
    assert g.subscriber.qos_incompatible == {"/scan": 1}


def test_remap_disable_and_namespace(graph) -> None:
    g = graph(
        TOPIC_REMAP="/odom=/wheel/odom", TOPICS_DISABLED="/gps/fix", TOPIC_NAMESPACE="/robot1"
    )
    wheel = g.robot.create_publisher(m.Odometry, "/wheel/odom", BEST_EFFORT)
    scan = g.robot.create_publisher(m.LaserScan, "/robot1/scan", BEST_EFFORT)
    unprefixed = g.robot.create_publisher(m.LaserScan, "/scan", BEST_EFFORT)
    gps = g.robot.create_publisher(m.NavSatFix, "/robot1/gps/fix", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    wheel.publish(odom(1.5))
    scan.publish(m.LaserScan(range_min=0.1, range_max=10.0, ranges=[2.0]))
    unprefixed.publish(m.LaserScan(range_min=0.1, range_max=10.0, ranges=[9.0]))
    gps.publish(m.NavSatFix(latitude=1.0, longitude=1.0))
    g.run(0.5)
    assert g.received("/odom") == 1 and g.received("/scan") == 1
    assert g.subscription("/gps/fix") is None and g.received("/gps/fix") == 0
    event = g.events[-1]
    assert event["location"]["local"]["x_m"] == 1.5
    assert math.isclose(event["perception"]["lidar"][0]["closest_range_m"], 2.0)


def test_a_publisher_of_another_type_is_ignored(graph) -> None:
    g = graph()
    publisher = g.robot.create_publisher(m.String, "/odom", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    publisher.publish(m.String(data="x"))
    g.run(0.3)
    assert g.subscription("/odom").type_name == "nav_msgs/msg/Odometry"  # its own type, still
    assert g.received("/odom") == 0


def test_twist_stamped_on_cmd_vel(graph) -> None:
    g = graph()
    publisher = g.robot.create_publisher(m.TwistStamped, "/cmd_vel", RELIABLE)
    g.run(GRAPH_CHECK_S + 0.1)
    msg = m.TwistStamped()
    msg.twist.linear = m.Vector3(x=0.7, y=0.0, z=0.0)
    publisher.publish(msg)
    g.run(0.5)
    assert g.events[-1]["motion"]["commanded_velocity"]["linear_x_mps"] == 0.7


def test_ros_parameters_are_a_settings_source(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SOURCE_ID", "from-env")
    assert (
        main(
            [
                "config",
                "--ros-args",
                "-p",
                "sample_rate_hz:=10.0",
                "-p",
                "source_id:=from-param",
                "-r",
                "__ns:=/robot1",
            ]
        )
        == 0
    )
    rows = {line.split()[0]: line.split()[1:] for line in capsys.readouterr().out.splitlines()}
    assert rows["SAMPLE_RATE_HZ"] == ["10.0", "ros", "param"]
    assert rows["SOURCE_ID"] == ["from-env", "env", "SOURCE_ID"]  # env outranks a ROS param


def test_extra_topics_take_their_type_from_the_graph(graph) -> None:
    from phytrace_edge.sim.mock_ros.message_base import MESSAGE_TYPES, declare

    g = graph(
        TOPICS_EXTRA="/motor/temperature rate_hz=100; /acme/drive mode=on_change",
        TOPIC_NAMESPACE="/robot1",
    )
    sensor = g.robot.create_publisher(m.Temperature, "/robot1/motor/temperature", RELIABLE)
    vendor = declare("acme_msgs/msg/DriveStatus", {"amps": "float"})
    g.robot.create_publisher(vendor, "/robot1/acme/drive", RELIABLE)
    del MESSAGE_TYPES["acme_msgs/msg/DriveStatus"]  # in the graph, not installed here
    g.run(GRAPH_CHECK_S + 0.1)
    assert g.subscription("/motor/temperature").type_name == "sensor_msgs/msg/Temperature"
    assert g.subscription("/acme/drive") is None
    stats = g.subscriber.stats()
    assert stats["/acme/drive"]["type_unknown"] == "acme_msgs/msg/DriveStatus"
    for celsius in (40.0, 41.5):
        sensor.publish(m.Temperature(temperature=celsius))
        g.run(0.3)
    topic_events = [e for e in g.events if e["event_type"] == "telemetry.topic"]
    assert [e["data"]["temperature"] for e in topic_events] == [40.0, 41.5]
    assert {e["topic"] for e in topic_events} == {"/motor/temperature"}  # the configured name


def test_an_rclpy_that_fails_to_import_says_why() -> None:
    from phytrace_edge.ingest.sources.ros import import_error_message

    not_sourced = import_error_message(ModuleNotFoundError("No module named 'rclpy'", name="rclpy"))
    assert "source ROS 2 first" in not_sourced
    missing = import_error_message(ModuleNotFoundError("No module named 'yaml'", name="yaml"))
    assert "No module named 'yaml'" in missing and "source ROS 2 first" not in missing
    broken = import_error_message(ImportError("libyaml.so: cannot open shared object file"))
    assert "libyaml.so" in broken


def test_state_streams_are_taken_at_the_tick_not_called_back(graph) -> None:
    """Odometry at 50 Hz into a 5 Hz sample tick: no callback per message, the newest
    message taken at each tick; diagnostics (every message counts) still called back.
    (No incident window: with one, /odom is called back on every message.)"""
    g = graph(SAMPLE_RATE_HZ="5", INCIDENT_RECORDING="false")
    odometry = g.robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    diagnostics = g.robot.create_publisher(m.DiagnosticArray, "/diagnostics", RELIABLE)
    g.run(GRAPH_CHECK_S + 0.1)
    ticks_before = len(g.events)
    for i in range(50):  # faster than the tick: several messages between two ticks
        odometry.publish(odom(float(i)))
        diagnostics.publish(m.DiagnosticArray())
        g.run(0.02)
    ticks = len(g.events) - ticks_before
    assert g.received("/diagnostics") == 50
    assert ticks < 25 and abs(g.received("/odom") - ticks) <= 1  # one per tick, no more
    assert g.events[-1]["location"]["local"]["x_m"] >= 48.0  # the newest at that tick


def test_a_window_topic_reaches_the_dispatcher_on_every_message(graph) -> None:
    """With the incident window kept (the default), odometry at 50 Hz reaches the
    dispatcher on every message (all those waiting, taken at the tick), and the tick's
    event still has the newest."""
    g = graph(SAMPLE_RATE_HZ="5")
    odometry = g.robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    for i in range(50):
        odometry.publish(odom(float(i)))
        g.run(0.02)
    assert g.received("/odom") == 50
    assert g.events[-1]["location"]["local"]["x_m"] >= 48.0


def test_an_incompatible_state_stream_is_counted_from_the_graph(graph) -> None:
    """No executor runs a state stream's event handlers: its QoS problems are read off
    the graph (a reliable request meets a best-effort lidar)."""
    g = graph(TOPIC_QOS="/scan=reliable")
    g.robot.create_publisher(m.LaserScan, "/scan", BEST_EFFORT)
    g.run(GRAPH_CHECK_S + 0.1)
    assert g.subscriber.stats()["/scan"]["qos_incompatible"] == 1


def test_a_state_stream_re_matched_at_the_graph_check_keeps_its_waiting_message(graph) -> None:
    """The graph check replaces the battery's subscription (best effort before the
    reliable publisher was seen) at the same moment as a tick: the message published
    since the last tick, still waiting in the old subscription, is handed over, not
    destroyed with it."""
    g = graph(SAMPLE_RATE_HZ="5")
    first = g.subscription("/battery_state")
    assert not first.qos.reliable
    battery = g.robot.create_publisher(m.BatteryState, "/battery_state", RELIABLE)
    g.run(1.0)
    battery.publish(m.BatteryState(voltage=20.0, percentage=0.5))
    g.run(0.95)  # past the tick at 1.8 s, before the check and the tick at 2.0 s
    battery.publish(m.BatteryState(voltage=21.0, percentage=0.5))
    g.run(0.1)
    replaced = g.subscription("/battery_state")
    assert replaced.handle is not first.handle and replaced.qos.reliable
    assert g.events[-1]["power"]["battery"]["voltage_v"] == 21.0


def test_a_message_taken_at_the_tick_carries_its_true_age(graph) -> None:
    """Odometry received 70 ms after a sample tick waits in its subscription until the
    next tick, 130 ms later: the event says age_s 0.13 (from the reception stamp the
    middleware gives with the message, as rclpy's take does), not 0.0."""
    g = graph(SAMPLE_RATE_HZ="5")  # ticks at 0.2, 0.4, ... s of virtual time
    odometry = g.robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    g.run_until(2.27)
    published_ns = g.context.time_source.system_ns()
    odometry.publish(odom(4.5))
    g.run_until(2.61)
    first, second = [e for e in g.events if "location" in e]
    assert [s["age_s"] for s in first["location"]["sources"]] == [0.13]
    assert [s["age_s"] for s in second["location"]["sources"]] == [0.33]  # not taken again
    assert g.received("/odom") == 1
    captured = datetime.fromisoformat(first["captured_at"].replace("Z", "+00:00")).timestamp()
    assert captured - 0.13 == pytest.approx(published_ns / 1e9, abs=0.001)


def test_an_extra_topic_is_taken_at_its_own_rate_not_at_every_tick(graph) -> None:
    """An extra topic at rate_hz=1 published at 20 Hz into a 5 Hz tick: taken (and so
    deserialised) once a second, not at every tick; each take is one event."""
    g = graph(
        SAMPLE_RATE_HZ="5",
        TOPICS_EXTRA="/motor/temperature rate_hz=1 type=sensor_msgs/msg/Temperature",
    )
    sensor = g.robot.create_publisher(m.Temperature, "/motor/temperature", RELIABLE)
    g.run_until(2.1)
    published = 0
    for step in range(200):  # 10 s at 20 Hz
        sensor.publish(m.Temperature(temperature=float(step)))
        published += 1
        g.run_until(2.1 + (step + 1) * 0.05)
    events = [e for e in g.events if e["event_type"] == "telemetry.topic"]
    assert published == 200
    assert g.received("/motor/temperature") == len(events) == 10
    assert g.source.topic_stats()["/motor/temperature"]["publishers"] == 1
    ticks = [e for e in g.events if e["event_type"] == "telemetry.periodic"]
    assert not ticks  # nothing else publishes: the extra topic alone, at its own rate


def test_rosout_records_have_an_age_in_status(graph) -> None:
    """/rosout is called back, not taken at the tick: its records have a last-seen age
    as the table's topics do (status showed null)."""
    g = graph()
    g.robot.get_logger().warning("starting")  # rcl's /rosout publisher: latched
    g.run_until(4.1)  # the graph checks have matched it
    assert g.received("/rosout") == 1
    g.robot.get_logger().warning("wheel slip")
    g.run_until(4.6)
    assert g.received("/rosout") == 2
    assert g.builder.topic_ages()["/rosout"] == pytest.approx(0.5, abs=0.001)
