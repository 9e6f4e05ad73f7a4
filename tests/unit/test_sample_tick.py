"""The sample tick goes one way (issue 34, item 3): the input's ``before_tick`` takes the
newest samples of its state topics and returns them; the sampler hands them to the
dispatcher, then builds. The input is given nothing to call back at the tick, and the
builder never calls into ingest."""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import pytest

from phytrace_edge.builder.sampler import Sampler, TickInput
from phytrace_edge.config import load_settings
from phytrace_edge.ingest.dispatch import Dispatcher, Take, TakenMessage, TakenUnreadable
from phytrace_edge.ingest.generic import rosidl_field_types
from phytrace_edge.ingest.sources.base import Feed, Finished
from phytrace_edge.ingest.sources.ros import RosSource
from phytrace_edge.ingest.sources.ros_graph import FULL_RATE_QUEUE_DEPTH
from phytrace_edge.runtime import options, wiring
from phytrace_edge.sim import mock_ros
from phytrace_edge.sim.mock_ros import as_rclpy
from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.sim.mock_ros.qos import QoSProfile, ReliabilityPolicy
from tests.unit.test_architecture import import_graph

BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def odom(x: float) -> m.Odometry:
    msg = m.Odometry()
    msg.pose.pose.position = m.Point(x=x, y=0.0, z=0.0)
    return msg


class TakingInput:
    """An input that reads its state topics at the tick: each ``before_tick`` returns
    the next of ``takes``. It is never started, so it holds no dispatcher or builder
    to call back: what it took can only reach them through the sampler."""

    keeps_time = False
    clock = None

    def __init__(self, takes: list[list[Take]], log: list[str]) -> None:
        self._takes, self._log = takes, log

    def field_types(self, msg: Any) -> Mapping[str, str]:
        return rosidl_field_types(msg)

    def start(self, feed: Feed) -> None:
        raise AssertionError("not started: the tick alone must carry what is taken")

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None:
        stop.wait()

    def before_tick(self) -> Sequence[Take]:
        self._log.append("take")
        return self._takes.pop(0) if self._takes else []

    def stop(self) -> None:
        pass

    def finished(self) -> Finished | None:
        return None

    def topic_stats(self) -> dict[str, dict[str, Any]]:
        return {}


def test_a_tick_takes_then_dispatches_then_builds_in_that_order() -> None:
    """The sampler calls the input's take, hands what it returned to the dispatcher
    (each message with its age), then builds: the event sees the taken message."""
    log: list[str] = []
    settings = load_settings(env={}).settings
    taken: list[Take] = [TakenMessage("/odom", odom(4.5), 0.25)]
    source = TakingInput([taken], log)
    pipeline = wiring.build_pipeline(settings, source, lambda built: log.append("emit"))
    builder, dispatcher = pipeline.builder, pipeline.dispatcher
    built_before = builder.build

    def build(captured_at_s: float | None = None) -> Any:
        log.append(f"build (/odom received {dispatcher.received['/odom']})")
        return built_before(captured_at_s)

    handed: list[Sequence[Take]] = []

    def dispatch(takes: Sequence[Take]) -> None:
        log.append(f"dispatch {[t.topic for t in takes]}")
        handed.append(takes)
        dispatcher.on_taken(takes)

    builder.build = build  # type: ignore[method-assign]
    events: list[dict[str, Any]] = []
    sampler = Sampler(
        builder,
        lambda built: events.append(built.event),
        settings.sample_rate_hz,
        TickInput(source.before_tick, dispatch),
    )
    assert sampler.tick() is True
    assert log == ["take", "dispatch ['/odom']", "build (/odom received 1)"]
    assert handed == [taken]  # the very value the input returned
    (event,) = events
    assert event["location"]["local"]["x_m"] == 4.5
    assert [s["age_s"] for s in event["location"]["sources"]] == [0.25]  # its age kept
    sampler.tick()  # nothing new taken: still take, dispatch, then build
    assert log[3:6] == ["take", "dispatch []", "build (/odom received 1)"]


def test_the_wiring_connects_the_take_to_the_dispatcher() -> None:
    """Through ``build_pipeline`` (as ``run`` wires it): a message and an unreadable
    sample taken at the tick are counted by the dispatcher as if called back, and the
    message is in the tick's event; the input was never started (no Feed)."""
    log: list[str] = []
    settings = load_settings(env={}).settings
    takes: list[Take] = [
        TakenUnreadable("/odom", "undecodable", "UnicodeDecodeError: ..."),
        TakenMessage("/odom", odom(7.0), 0.0),
    ]
    events: list[dict[str, Any]] = []
    pipeline = wiring.build_pipeline(
        settings, TakingInput([takes], log), lambda built: events.append(built.event)
    )
    assert pipeline.sampler.tick() is True
    assert pipeline.dispatcher.received["/odom"] == 2
    assert dict(pipeline.dispatcher.rejected) == {("/odom", "undecodable"): 1}
    assert events[-1]["location"]["local"]["x_m"] == 7.0


def test_the_dispatcher_hands_over_takes_in_order_with_their_ages() -> None:
    readings: list[tuple[str, float]] = []
    dispatcher = Dispatcher(lambda topic, reading, age_s: readings.append((topic, age_s)))
    dispatcher.on_taken(
        [
            TakenMessage("/odom", odom(1.0), 0.5),
            TakenUnreadable("/imu", "undecodable", "bad"),
            TakenMessage("/odom", odom(2.0), 0.125),
        ]
    )
    assert readings == [("/odom", 0.5), ("/odom", 0.125)]
    assert (dispatcher.received["/odom"], dispatcher.received["/imu"]) == (2, 1)
    assert dict(dispatcher.rejected) == {("/imu", "undecodable"): 1}


@pytest.fixture(params=["false"])
def ros_input(request: pytest.FixtureRequest):
    """The ros input over the mock rclpy, started with a feed that records what it is
    called back with; a robot node publishes on the same graph."""
    context = mock_ros.Context(virtual_time=True)
    modules = as_rclpy.modules(context)
    modules["rclpy"].init()
    # no incident window: the newest message of each state stream is taken at the tick
    # (with one, every message of the window's topics:
    # test_a_window_topic_gives_every_message_at_the_tick)
    env = {"BRIDGE_INPUT": "ros", "INCIDENT_RECORDING": request.param}
    settings = load_settings(env=env).settings
    source = RosSource(options.source_options(settings, {}), modules.__getitem__)
    called_back: list[str] = []

    def on_message(topic: str, msg: Any, age_s: float = 0.0) -> None:
        called_back.append(topic)

    source.start(Feed(on_message, lambda at: True, 0.2))
    robot = source.api.create_node("robot")
    source.executor.add_node(robot)

    def spin(seconds: float) -> None:
        end = context.time_source.steady_ns() + int(seconds * 1e9)
        while context.time_source.steady_ns() < end:
            source.executor.spin_once(timeout_sec=0.05)

    yield source, robot, spin, called_back
    source.stop()
    mock_ros.shutdown(context=context)


def test_the_ros_input_returns_what_it_takes_and_calls_nothing_back(ros_input) -> None:
    """Odometry (a state stream) is taken at the tick: ``before_tick`` returns it with
    its age, once, and the feed is never called for it; diagnostics (every message
    counts) are still called back as they arrive."""
    source, robot, spin, called_back = ros_input
    odometry = robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    diagnostics = robot.create_publisher(m.DiagnosticArray, "/diagnostics", RELIABLE)
    spin(0.5)
    odometry.publish(odom(1.0))
    odometry.publish(odom(1.5))  # the newest is what a tick takes
    diagnostics.publish(m.DiagnosticArray(status=[m.DiagnosticStatus(name="motor")]))
    spin(0.3)
    taken = source.before_tick()
    assert [(t.topic, t.message.pose.pose.position.x) for t in taken] == [("/odom", 1.5)]
    assert all(isinstance(t, TakenMessage) and 0.0 <= t.age_s <= 0.8 for t in taken)
    assert called_back == ["/diagnostics"]
    assert list(source.before_tick()) == []  # taken once


@pytest.mark.parametrize("ros_input", ["true"], indirect=True)
def test_a_window_topic_gives_every_message_at_the_tick(ros_input) -> None:
    """While an incident window is kept (INCIDENT_RECORDING), every message of its
    topics (/odom among them) is taken at the tick, oldest first, each with its own
    age; none is called back (a callback costs rclpy's executor more than the
    message)."""
    source, robot, spin, called_back = ros_input
    odometry = robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    spin(0.5)
    for x in (1.0, 1.5, 2.0):
        odometry.publish(odom(x))
        spin(0.05)
    spin(0.3)
    taken = list(source.before_tick())
    assert [(t.topic, t.message.pose.pose.position.x) for t in taken] == [
        ("/odom", 1.0),
        ("/odom", 1.5),
        ("/odom", 2.0),
    ]
    # received 50 ms apart; the newest 0.05 + 0.3 s of virtual time before the take
    assert [round(t.age_s, 2) for t in taken] == [0.45, 0.4, 0.35]
    assert called_back == []
    assert list(source.before_tick()) == []  # taken once


@pytest.mark.parametrize("ros_input", ["true"], indirect=True)
def test_a_full_rate_queue_found_full_is_counted(ros_input) -> None:
    """More messages between two ticks than a full-rate subscription keeps: the
    oldest are replaced, the take gets the newest FULL_RATE_QUEUE_DEPTH, and
    ``topic_stats`` counts the topic's queue as found full."""
    source, robot, spin, _ = ros_input
    odometry = robot.create_publisher(m.Odometry, "/odom", BEST_EFFORT)
    spin(0.5)
    published = FULL_RATE_QUEUE_DEPTH + 20
    for x in range(published):
        odometry.publish(odom(float(x)))
    spin(0.05)
    taken = list(source.before_tick())
    assert [t.message.pose.pose.position.x for t in taken] == [
        float(x) for x in range(published - FULL_RATE_QUEUE_DEPTH, published)
    ]
    assert source.topic_stats()["/odom"]["queue_full"] == 1
    assert "queue_full" not in source.topic_stats()["/imu/data"]


def test_the_sampler_imports_nothing_of_ingest() -> None:
    """The sampler only passes what is taken on: it knows neither the inputs nor the
    dispatcher (both given at wiring, ``TickInput``)."""
    imports = import_graph()["phytrace_edge.builder.sampler"]
    assert not {i for i in imports if i.startswith("phytrace_edge.ingest")}, imports


def test_no_module_of_the_builder_imports_the_dispatcher_or_an_input() -> None:
    """The builder may read ingest's vocabulary (readings, topics), never its moving
    parts: the dispatcher and the inputs."""
    moving = ("phytrace_edge.ingest.dispatch", "phytrace_edge.ingest.sources")
    found = {
        module: sorted(i for i in imports if i.startswith(moving))
        for module, imports in import_graph().items()
        if module.startswith("phytrace_edge.builder")
    }
    assert {module: i for module, i in found.items() if i} == {}
