"""UDMBuilder: absent/stale domains, latched topics, accumulation between ticks, threads."""

from __future__ import annotations

import threading

import pytest

from phytrace_edge.builder.assemble import classify_stamp
from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.udm.schema import find_violation
from tests.conftest import FakeClock

IDENTITY = Identity("bot-1", "amr", fleet_id="fleet-a")
ODOM = {
    "stamp_ns": 1_763_000_000_000_000_000,
    "frame_id": "odom",
    "local": {"coordinate_frame": "odom", "x_m": 1.0, "y_m": 2.0, "yaw_deg": 90.0},
    "linear_velocity": {"x_mps": 0.5, "y_mps": 0.0, "z_mps": 0.0},
    "angular_velocity": {"yaw_dps": 0.0},
}


def statuses(*pairs: tuple[str, str]) -> dict:
    return {"statuses": [{"name": name, "level": level, "message": "m"} for name, level in pairs]}


def delivery(state: str, order: str = "order-1") -> dict:
    return {
        "payload": {"order_id": order, "delivery_state": state},
        "task": {"task_id": order},
    }


@pytest.fixture
def builder(clock: FakeClock) -> UDMBuilder:
    return UDMBuilder(BuilderOptions(IDENTITY, stale_after_s=5.0), clock=clock)


def test_no_topics_means_no_domains(builder: UDMBuilder) -> None:
    event = builder.build().event
    assert set(event) == {
        "event_id",
        "event_type",
        "schema_version",
        "captured_at",
        "source_id",
        "source_type",
        "identity",
    }
    assert event["identity"] == {"source_id": "bot-1", "source_type": "amr", "fleet_id": "fleet-a"}
    assert find_violation(event) is None


def test_odometry_fills_location_and_motion_with_sources(
    builder: UDMBuilder, clock: FakeClock
) -> None:
    builder.add_reading("/odom", ODOM)
    clock.advance(0.25)
    event = builder.build().event
    assert event["location"]["local"]["x_m"] == 1.0
    assert "latitude" not in event["location"]  # no GPS, no invented coordinates
    assert event["motion"]["motion_state"] == "moving"
    assert event["motion"]["speed_mps"] == 0.5
    assert event["location"]["sources"] == [
        {"topic": "/odom", "age_s": 0.25, "clock": "epoch", "stamp": "2025-11-13T02:13:20.000Z"}
    ]
    assert "power" not in event
    assert find_violation(event) is None


def test_stale_sampled_topic_leaves_the_event(builder: UDMBuilder, clock: FakeClock) -> None:
    builder.add_reading("/odom", ODOM)
    clock.advance(5.0)
    assert "location" in builder.build().event
    clock.advance(0.1)
    event = builder.build().event
    assert "location" not in event and "motion" not in event
    assert builder.stale_omissions["/odom"] == 1


def test_latched_goal_and_delivery_survive_staleness(builder: UDMBuilder, clock: FakeClock) -> None:
    builder.add_reading("/goal_pose", {"goal": {"frame_id": "map", "x_m": 4.0, "y_m": 2.0}})
    builder.add_reading("/delivery/status", delivery("in_transit"))
    clock.advance(60.0)
    event = builder.build().event
    assert event["navigation"]["goal"]["x_m"] == 4.0
    assert event["payload"]["delivery_state"] == "in_transit"
    assert event["navigation"]["sources"][0]["age_s"] == 60.0


def test_transient_diagnostic_error_between_ticks_is_reported_once(
    builder: UDMBuilder, clock: FakeClock
) -> None:
    builder.add_reading("/diagnostics", statuses(("motor", "ok")))
    builder.build()
    builder.add_reading("/diagnostics", statuses(("motor", "error")))
    clock.advance(0.05)
    builder.add_reading("/diagnostics", statuses(("motor", "ok")))
    first = builder.build().event["operational"]["errors"]
    assert len(first) == 1
    assert first[0]["name"] == "motor" and first[0]["level"] == "error"
    assert first[0]["active"] is False and first[0]["occurrences"] == 1
    assert builder.build().event["operational"]["errors"] == []


def test_persistent_error_is_active_in_every_event_until_cleared(
    builder: UDMBuilder, clock: FakeClock
) -> None:
    builder.add_reading("/diagnostics", statuses(("wifi", "warn"), ("lidar", "ok")))
    for _ in range(3):
        errors = builder.build().event["operational"]["errors"]
        assert [(e["name"], e["level"], e["active"]) for e in errors] == [("wifi", "warn", True)]
        clock.advance(0.2)
    builder.add_reading("/diagnostics", statuses(("wifi", "ok")))
    assert builder.build().event["operational"]["errors"] == []


def test_worst_level_between_ticks_wins(builder: UDMBuilder) -> None:
    builder.add_reading("/diagnostics", statuses(("motor", "warn")))
    builder.add_reading("/diagnostics", statuses(("motor", "error")))
    builder.add_reading("/diagnostics", statuses(("motor", "warn")))
    (error,) = builder.build().event["operational"]["errors"]
    assert error["level"] == "error" and error["occurrences"] == 3 and error["active"] is True


def test_errors_of_stale_diagnostics_are_not_active(builder: UDMBuilder, clock: FakeClock) -> None:
    builder.add_reading("/diagnostics", statuses(("motor", "error")))
    builder.build()
    clock.advance(10.0)
    event = builder.build().event
    assert "operational" not in event


def test_delivery_transitions_between_ticks_are_kept(builder: UDMBuilder, clock: FakeClock) -> None:
    builder.add_reading("/delivery/status", delivery("in_transit"))
    builder.build()
    for state in ("arriving", "delivered", "delivered", "returning"):
        clock.advance(0.01)
        builder.add_reading("/delivery/status", delivery(state))
    event = builder.build().event
    transitions = event["operational"]["transitions"]
    assert [(t.get("from"), t["to"]) for t in transitions] == [
        ("in_transit", "arriving"),
        ("arriving", "delivered"),
        ("delivered", "returning"),
    ]
    assert event["payload"]["delivery_state"] == "returning"
    assert "transitions" not in builder.build().event["operational"]
    assert find_violation(event) is None


def test_new_goals_between_ticks_are_all_reported(builder: UDMBuilder) -> None:
    for x in (1.0, 2.0, 3.0):
        builder.add_reading("/goal_pose", {"goal": {"frame_id": "map", "x_m": x, "y_m": 0.0}})
    event = builder.build().event
    assert [g["x_m"] for g in event["navigation"]["new_goals"]] == [1.0, 2.0, 3.0]
    assert event["navigation"]["goal"]["x_m"] == 3.0
    assert "new_goals" not in builder.build().event["navigation"]


def test_a_replayed_goal_is_not_a_new_goal(builder: UDMBuilder) -> None:
    """A latched goal replayed (same stamp, same pose) when the subscription is
    re-created as transient-local; the same pose with a new stamp is a new goal."""
    goal = {"frame_id": "map", "x_m": 45.0, "y_m": 22.0, "yaw_deg": 90.0}
    builder.add_reading("/goal_pose", {"goal": goal, "stamp_ns": 1_000})
    assert len(builder.build().event["navigation"]["new_goals"]) == 1
    builder.add_reading("/goal_pose", {"goal": dict(goal), "stamp_ns": 1_000})  # the replay
    assert "new_goals" not in builder.build().event["navigation"]
    builder.add_reading("/goal_pose", {"goal": dict(goal), "stamp_ns": 2_000})  # sent again
    assert len(builder.build().event["navigation"]["new_goals"]) == 1


def test_heading_needs_gps_and_imu_and_is_a_compass_heading(builder: UDMBuilder) -> None:
    builder.add_reading(
        "/imu/data", {"imu": {"orientation_deg": {"roll": 0, "pitch": 0, "yaw": 0.0}}}
    )
    assert "location" not in builder.build().event
    builder.add_reading(
        "/gps/fix", {"gps": {"fix_type": "3d_fix", "latitude": 41.0, "longitude": -87.0}}
    )
    location = builder.build().event["location"]
    assert location["heading_deg"] == 90.0  # ENU yaw 0 faces east
    assert location["coordinate_system"] == "WGS84"


@pytest.mark.parametrize(
    ("stamp_ns", "sim", "expected"),
    [
        (None, False, {"clock": "none"}),
        (12_500_000_000, False, {"clock": "non_epoch", "stamp_s": 12.5}),
        (12_500_000_000, True, {"clock": "sim", "stamp_s": 12.5}),
        (1_736_950_981_042_000_000, False, {"clock": "epoch", "stamp": "2025-01-15T14:23:01.042Z"}),
        (4_000_000_000 * 10**9, False, {"clock": "non_epoch", "stamp_s": 4e9}),
    ],
)
def test_stamp_classification(stamp_ns: int | None, sim: bool, expected: dict) -> None:
    assert classify_stamp(stamp_ns, 1_763_000_000.0, sim) == expected


def test_captured_at_override_for_replay(builder: UDMBuilder) -> None:
    assert builder.build(captured_at_s=1736950981.042).event["captured_at"] == (
        "2025-01-15T14:23:01.042Z"
    )


def test_concurrent_callbacks_and_ticks(clock: FakeClock) -> None:
    builder = UDMBuilder(BuilderOptions(IDENTITY, stale_after_s=5.0), clock=clock)
    per_thread = 2000
    errors_seen: list[dict] = []

    def publish(thread: int) -> None:
        for i in range(per_thread):
            level = "error" if i % 2 else "ok"
            builder.add_reading("/diagnostics", statuses((f"t{thread}", level)))
            builder.add_reading("/odom", ODOM)

    threads = [threading.Thread(target=publish, args=(n,)) for n in range(4)]
    for thread in threads:
        thread.start()
    while any(thread.is_alive() for thread in threads):
        errors_seen.extend(builder.build().event.get("operational", {}).get("errors", []))
    for thread in threads:
        thread.join()
    errors_seen.extend(builder.build().event["operational"]["errors"])
    # every error occurrence is counted exactly once across all events
    assert sum(e.get("occurrences", 0) for e in errors_seen) == 4 * per_thread // 2


def test_event_classes_mark_what_must_never_be_thinned(
    builder: UDMBuilder, clock: FakeClock
) -> None:
    def tick(**readings: dict) -> bool:
        for name, reading in readings.items():
            topic = {"delivery_status": "/delivery/status"}.get(name, f"/{name}")
            builder.add_reading(topic, reading)
        clock.advance(0.2)
        builder.add_reading("/odom", ODOM)
        return builder.build().important

    assert builder.build().important is False, "no data yet: nothing to mark"
    assert tick() is True, "the first event with data"
    assert tick() is False, "then periodic"
    assert tick(diagnostics=statuses(("motor", "error"))) is True, "an alarm is raised"
    assert tick(diagnostics=statuses(("motor", "error"))) is False, "and stays: periodic"
    assert tick(diagnostics=statuses(("motor", "warn"))) is True, "the alarm clears"
    assert tick(diagnostics=statuses(("motor", "warn"))) is False
    assert tick(diagnostics=statuses(("lidar", "stale"))) is True, "STALE is an alarm too"
    assert tick(delivery_status=delivery("loading")) is True, "a transition"
    assert tick(delivery_status=delivery("loading")) is False
    goal = {"goal": {"frame_id": "map", "x_m": 1.0, "y_m": 2.0, "yaw_deg": 0.0}}
    assert tick(goal_pose=goal) is True, "a new goal"
    clock.advance(6.0)  # nothing heard for longer than STALE_AFTER_S
    assert tick() is True, "the first data after a gap"
    assert tick() is False


@pytest.mark.parametrize("unsynchronized", [True, False])
def test_events_stamped_on_an_unsynchronized_clock_say_so(
    clock: FakeClock, unsynchronized: bool
) -> None:
    builder = UDMBuilder(
        BuilderOptions(IDENTITY), clock=clock, unsynchronized=lambda: unsynchronized
    )
    builder.add_reading("/rosout", {"level": "error", "logger": "nav", "message": "stuck"})
    events = [builder.build().event, *(built.event for built in builder.side_events())]
    assert len(events) == 2
    for event in events:
        assert find_violation(event) is None
        marked = event.get("wall_clock") == {"synchronized": False}
        assert marked is unsynchronized


def test_bag_time_is_never_marked(clock: FakeClock) -> None:
    """A replay passes the bag's time: not this machine's clock, whatever the kernel says."""
    builder = UDMBuilder(BuilderOptions(IDENTITY), clock=clock, unsynchronized=lambda: True)
    assert "wall_clock" not in builder.build(captured_at_s=1_700_000_000.0).event
