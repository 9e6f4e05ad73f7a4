"""The mock rclpy layer behaves like rclpy where the bridge depends on it."""

from __future__ import annotations

import array
import math

import numpy as np
import pytest

from phytrace_edge.sim import mock_ros
from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.sim.mock_ros.qos import (
    DurabilityPolicy,
    QoSPolicyKind,
    QoSProfile,
    ReliabilityPolicy,
)
from phytrace_edge.sim.mock_ros.runtime import SubscriptionEventCallbacks


@pytest.fixture
def context() -> mock_ros.Context:
    # instant discovery: these tests are about other things (discovery has its own)
    ctx = mock_ros.Context(virtual_time=True, discovery_latency_s=0.0)
    mock_ros.init(context=ctx)
    yield ctx
    mock_ros.shutdown(context=ctx)


def test_field_types_are_those_of_rclpy() -> None:
    battery = m.BatteryState(cell_voltage=[4.0, 4.1])
    assert isinstance(battery.cell_voltage, array.array) and battery.cell_voltage.typecode == "f"
    assert isinstance(m.JointState(position=[1.0]).position, array.array)
    assert m.JointState(position=[1.0]).position.typecode == "d"
    imu = m.Imu()
    assert isinstance(imu.orientation_covariance, np.ndarray)
    assert imu.orientation_covariance.dtype == np.float64 and imu.orientation_covariance.shape == (
        9,
    )
    assert m.Odometry().pose.covariance.shape == (36,)
    assert m.DiagnosticStatus().level == b"\x00"
    assert m.DiagnosticStatus.ERROR == b"\x02"
    assert isinstance(m.NavSatFix().status.status, int)
    assert m.Quaternion().w == 1.0
    assert m.BatteryState.get_fields_and_field_types()["cell_voltage"] == "sequence<float>"


@pytest.mark.parametrize(
    ("make", "error"),
    [
        (lambda: m.BatteryState(voltage=24), "must be of type 'float'"),
        (lambda: m.DiagnosticStatus(level=2), "bytes"),
        (lambda: m.NavSatStatus(status=200), "integer in"),
        (lambda: m.Imu(orientation_covariance=[0.0] * 8), "sequence of 9"),
        (lambda: m.String(data=5), "str"),
        (lambda: m.Odometry(header=m.String()), "sub message"),
        (lambda: m.Odometry(frame="x"), "Invalid arguments"),
    ],
)
def test_setters_reject_wrong_types_like_rclpy(make, error: str) -> None:
    with pytest.raises(AssertionError, match=error):
        make()


def test_float32_allows_inf_and_nan_like_rclpy() -> None:
    assert math.isinf(m.LaserScan(range_max=math.inf).range_max)
    assert math.isnan(m.BatteryState(percentage=math.nan).percentage)


def test_unknown_attribute_is_an_error() -> None:
    with pytest.raises(AttributeError):
        m.String().value = "x"  # type: ignore[attr-defined]


def _spin_until_idle(
    context: mock_ros.Context, *nodes: mock_ros.Node, seconds: float = 0.5
) -> None:
    executor = mock_ros.SingleThreadedExecutor(context, list(nodes))
    end = context.time_source.steady_ns() + int(seconds * 1e9)
    while context.time_source.steady_ns() < end:
        executor.spin_once(timeout_sec=0.05)


def test_reliable_subscription_gets_nothing_from_best_effort_publisher(
    context: mock_ros.Context,
) -> None:
    node = mock_ros.create_node("n", context=context)
    received: list = []
    events: list = []
    best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    publisher = node.create_publisher(m.String, "/t", best_effort)
    node.create_subscription(
        m.String,
        "/t",
        received.append,
        QoSProfile(depth=5),
        event_callbacks=SubscriptionEventCallbacks(incompatible_qos=events.append),
    )
    node.create_subscription(m.String, "/t", received.append, best_effort)
    publisher.publish(m.String(data="hello"))
    _spin_until_idle(context, node)
    assert [msg.data for msg in received] == ["hello"]  # only the best-effort reader
    assert len(events) == 1 and events[0].last_policy_kind == QoSPolicyKind.RELIABILITY


def test_discovery_takes_time_and_what_is_published_before_is_lost() -> None:
    context = mock_ros.Context(virtual_time=True, discovery_latency_s=0.2)
    mock_ros.init(context=context)
    try:
        node = mock_ros.create_node("n", context=context)
        received: list = []
        node.create_subscription(m.String, "/t", received.append, 10)
        publisher = node.create_publisher(m.String, "/t", 10)
        publisher.publish(m.String(data="too early"))
        assert node.get_publishers_info_by_topic("/t") == []  # not discovered yet
        _spin_until_idle(context, node, seconds=0.3)
        assert len(node.get_publishers_info_by_topic("/t")) == 1
        publisher.publish(m.String(data="matched"))
        _spin_until_idle(context, node, seconds=0.1)
        assert [msg.data for msg in received] == ["matched"]
    finally:
        mock_ros.shutdown(context=context)


def test_subscriber_gets_a_copy(context: mock_ros.Context) -> None:
    node = mock_ros.create_node("n", context=context)
    received: list = []
    publisher = node.create_publisher(m.String, "/t", 10)
    node.create_subscription(m.String, "/t", received.append, 10)
    msg = m.String(data="a")
    publisher.publish(msg)
    msg.data = "changed"
    _spin_until_idle(context, node)
    assert received[0].data == "a"


def test_keep_last_depth_drops_oldest(context: mock_ros.Context) -> None:
    node = mock_ros.create_node("n", context=context)
    received: list = []
    publisher = node.create_publisher(m.String, "/t", 10)
    node.create_subscription(m.String, "/t", received.append, 3)
    for i in range(10):
        publisher.publish(m.String(data=str(i)))
    _spin_until_idle(context, node)
    assert [msg.data for msg in received] == ["7", "8", "9"]


def test_transient_local_replays_to_late_transient_local_subscriber(
    context: mock_ros.Context,
) -> None:
    node = mock_ros.create_node("n", context=context)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    publisher = node.create_publisher(m.String, "/latched", latched)
    publisher.publish(m.String(data="old"))
    publisher.publish(m.String(data="latest"))
    late: list = []
    volatile: list = []
    node.create_subscription(m.String, "/latched", late.append, latched)
    node.create_subscription(m.String, "/latched", volatile.append, 1)
    _spin_until_idle(context, node)
    assert [msg.data for msg in late] == ["latest"]
    assert volatile == []


def test_virtual_time_timers_fire_at_their_period(context: mock_ros.Context) -> None:
    node = mock_ros.create_node("n", context=context)
    fired: list[int] = []
    clock = mock_ros.Clock(clock_type=mock_ros.ClockType.STEADY_TIME, source=context.time_source)
    node.create_timer(0.1, lambda: fired.append(clock.now().nanoseconds), clock=clock)
    _spin_until_idle(context, node, seconds=1.0)
    assert len(fired) == 10
    assert np.diff(fired).tolist() == [100_000_000] * 9


def test_graph_reports_publishers_with_qos(context: mock_ros.Context) -> None:
    node = mock_ros.create_node("robot", context=context)
    node.create_publisher(m.LaserScan, "/scan", mock_ros.qos.qos_profile_sensor_data)
    (info,) = node.get_publishers_info_by_topic("/scan")
    assert info.node_name == "robot"
    assert info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT


def test_float32_fields_arrive_rounded_like_through_the_middleware(context) -> None:
    node = mock_ros.create_node("n", context=context)
    received: list = []
    publisher = node.create_publisher(m.LaserScan, "/scan", 10)
    node.create_subscription(m.LaserScan, "/scan", received.append, 10)
    publisher.publish(m.LaserScan(range_min=0.12, angle_increment=0.1))
    _spin_until_idle(context, node)
    assert received[0].range_min == pytest.approx(0.12) and received[0].range_min != 0.12
    assert received[0].range_min == float(np.float32(0.12))


def test_parameters_are_declared_before_they_are_read_as_in_rclpy(
    context: mock_ros.Context,
) -> None:
    from phytrace_edge.sim.mock_ros.parameters import (
        ParameterAlreadyDeclaredException,
        ParameterNotDeclaredException,
    )

    node = mock_ros.create_node("n", context=context)
    assert node.get_parameter("use_sim_time").value is False  # the node declares it
    with pytest.raises(ParameterNotDeclaredException):
        node.get_parameter("source_id")
    node.declare_parameter("source_id", "amr-7")
    assert node.get_parameter("source_id").value == "amr-7"
    with pytest.raises(ParameterAlreadyDeclaredException):
        node.declare_parameter("source_id", "again")


def test_the_sim_input_declares_the_settings_read_only_without_the_key() -> None:
    from phytrace_edge.config import load_settings
    from phytrace_edge.ingest.sources.base import Feed
    from phytrace_edge.ingest.sources.sim import SimSource
    from phytrace_edge.runtime import wiring

    settings = load_settings(
        env={"SOURCE_ID": "amr-7", "SAMPLE_RATE_HZ": "2", "PHYCLOUD_API_KEY": "secret-key"}
    ).settings
    source = SimSource(wiring.source_options(settings.replace(bridge_input="sim"), {}))
    source.start(Feed(lambda topic, msg: None, lambda at: True, 0.5))
    try:
        (node,) = [n for n in source._context.nodes if n.get_name() == "phytrace_edge"]
        assert node.get_parameter("source_id").value == "amr-7"
        assert node.get_parameter("sample_rate_hz").value == 2.0
        assert node.get_parameter("source_id").descriptor.read_only
        assert not node.has_parameter("phycloud_api_key")
    finally:
        source.stop()
