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
    ctx = mock_ros.Context(virtual_time=True, discovery_latency_s=0.0, subscription_side_lag_s=0.0)
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


@pytest.mark.parametrize(("subscription", "heard"), [("reliable", True), ("best_effort", False)])
def test_the_publishers_side_matches_first(subscription: str, heard: bool) -> None:
    """A reliable publisher whose subscription count already says 1 publishes at once:
    a reliable subscription gets it (resent once its side has matched), a best-effort
    one drops it (measured on Fast DDS, and the mock does the same)."""
    context = mock_ros.Context(virtual_time=True, discovery_latency_s=0.05)
    mock_ros.init(context=context)
    try:
        node = mock_ros.create_node("n", context=context)
        received: list = []
        reliability = ReliabilityPolicy[subscription.upper()]
        node.create_subscription(
            m.String, "/t", received.append, QoSProfile(depth=10, reliability=reliability)
        )
        publisher = node.create_publisher(m.String, "/t", QoSProfile(depth=10))
        while publisher.get_subscription_count() == 0:
            _spin_until_idle(context, node, seconds=0.01)
        publisher.publish(m.String(data="at once"))
        _spin_until_idle(context, node, seconds=0.5)
        assert [msg.data for msg in received] == (["at once"] if heard else [])
    finally:
        mock_ros.shutdown(context=context)


def test_an_executor_leaves_alone_what_its_callback_group_refuses(
    context: mock_ros.Context,
) -> None:
    from phytrace_edge.sim.mock_ros.callback_groups import CallbackGroup

    class Never(CallbackGroup):
        def can_execute(self, entity: object) -> bool:
            return False

    node = mock_ros.create_node("n", context=context)
    called: list = []
    publisher = node.create_publisher(m.String, "/t", 10)
    taken = node.create_subscription(m.String, "/t", called.append, 1, callback_group=Never())
    publisher.publish(m.String(data="a"))
    publisher.publish(m.String(data="b"))
    _spin_until_idle(context, node)
    assert called == []
    assert taken.handle.take_message(m.String, False)[0].data == "b"  # depth 1: the newest
    assert taken.handle.take_message(m.String, False) is None


def test_parameter_services_answer_only_while_an_executor_spins_the_node() -> None:
    """A node that no executor spins offers its services and never answers them: a
    client such as ``ros2 param list`` waits for ever (what rclpy does)."""
    import threading

    from phytrace_edge.sim.mock_ros.services import AsyncParameterClient

    context = mock_ros.Context(discovery_latency_s=0.0)  # real time: two threads
    mock_ros.init(context=context)
    try:
        spun = mock_ros.create_node("spun", context=context)
        spun.declare_parameter("source_id", "amr-7")
        mock_ros.create_node("idle", context=context)
        client_node = mock_ros.create_node("client", context=context)
        executor = mock_ros.SingleThreadedExecutor(context, [spun])
        stop = threading.Event()

        def spin() -> None:
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.05)

        spinner = threading.Thread(target=spin)
        spinner.start()
        client_executor = mock_ros.SingleThreadedExecutor(context, [client_node])
        for name, answers in (("/spun", True), ("/idle", False)):
            client = AsyncParameterClient(client_node, name)
            assert client.wait_for_services(timeout_sec=1.0)  # advertised either way
            future = client.list_parameters()
            client_executor.spin_until_future_complete(future, timeout_sec=1.0)
            assert future.done() is answers
        stop.set()
        spinner.join()
        assert "source_id" in future_names(client_node, "/spun", executor)
    finally:
        mock_ros.shutdown(context=context)


def future_names(client_node: mock_ros.Node, node: str, executor: object) -> list[str]:
    from phytrace_edge.sim.mock_ros.services import AsyncParameterClient

    future = AsyncParameterClient(client_node, node).list_parameters()
    executor.spin_until_future_complete(future, timeout_sec=1.0)  # type: ignore[attr-defined]
    return list(future.result().result.names)


def test_command_line_parameters_override_declared_values(tmp_path) -> None:
    params = tmp_path / "p.yaml"
    params.write_text("/n:\n  ros__parameters:\n    a: from-file\n    b: 2.0\n")
    context = mock_ros.Context(virtual_time=True)
    mock_ros.init(
        ["x", "--ros-args", "--params-file", str(params), "-p", "b:=3.5"], context=context
    )
    try:
        node = mock_ros.create_node("n", context=context)
        assert node.declare_parameter("a", "declared").value == "from-file"
        assert node.declare_parameter("b", 1.0).value == 3.5  # the later -p wins
        assert node.declare_parameter("c", "mine", ignore_override=True).value == "mine"
        kept = node.declare_parameter("d", "declared")
        assert kept.value == "declared"
        other = mock_ros.create_node("other", context=context)
        assert other.declare_parameter("a", "declared").value == "declared"  # not its section
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
    from phytrace_edge.runtime import options

    settings = load_settings(
        env={"SOURCE_ID": "amr-7", "SAMPLE_RATE_HZ": "2", "PHYCLOUD_API_KEY": "secret-key"}
    ).settings
    source = SimSource(options.source_options(settings.replace(bridge_input="sim"), {}))
    source.start(Feed(lambda topic, msg: None, lambda at: True, 0.5))
    try:
        (node,) = [n for n in source._context.nodes if n.get_name() == "phytrace_edge"]
        assert node.get_parameter("source_id").value == "amr-7"
        assert node.get_parameter("sample_rate_hz").value == 2.0
        assert node.describe_parameter("source_id").read_only
        assert not node.has_parameter("phycloud_api_key")
    finally:
        source.stop()
