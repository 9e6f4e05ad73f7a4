"""The side events of a tick: extra topics' rate limits and change detection, /rosout's
level filter and burst limit, and the events' schema."""

from __future__ import annotations

import pytest

from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.log_records import LogRecords
from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.builder.topic_events import TopicEvents, changed
from phytrace_edge.ingest.generic import rosidl_field_types
from phytrace_edge.ingest.rosout import handle_log
from phytrace_edge.ingest.topics import ExtraTopic
from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.udm.schema import find_violation


def temperature(celsius: float) -> m.Message:
    return m.Temperature(temperature=celsius, variance=0.0)


def events_for(extra: ExtraTopic, arrivals: list[tuple[float, float]], ticks: list[float]):
    """Feed (time, value) arrivals and take at tick times; (time, value) of each sample."""
    events = TopicEvents([extra], rosidl_field_types, 256)
    out = []
    moments = sorted([(t, "msg", v) for t, v in arrivals] + [(t, "tick", None) for t in ticks])
    for at, kind, value in moments:
        if kind == "msg":
            events.offer(extra.name, temperature(value), at)
        else:
            out += [(at, s.data["temperature"]) for s in events.take(at)]
    return out, events


def test_a_fast_topic_is_sampled_at_its_rate_and_its_last_value_is_not_lost() -> None:
    extra = ExtraTopic("/motor/temperature", rate_hz=2.0)
    arrivals = [(i * 0.1, float(i)) for i in range(25)]  # 10 Hz for 2.5 s, then silence
    ticks = [i * 0.2 + 0.05 for i in range(20)]  # the sample tick, 5 Hz
    sent, events = events_for(extra, arrivals, ticks)
    values = [value for _, value in sent]
    assert len(values) == 6  # 2.5 s at 2 Hz, plus the latest when it was next due
    assert values[0] == 0.0  # the first message goes out at once
    assert values[-1] == 24.0  # the last before silence is sent when it is due
    assert events.stats()["/motor/temperature"]["events"] == 6


def test_on_change_sends_only_changes_beyond_the_deadband() -> None:
    extra = ExtraTopic("/motor/temperature", rate_hz=100.0, mode="on_change", deadband=0.5)
    readings = [40.0, 40.2, 40.4, 40.6, 40.6, 41.2, 41.0, 39.9]
    arrivals = [(i * 1.0, v) for i, v in enumerate(readings)]
    sent, events = events_for(extra, arrivals, [i + 0.5 for i in range(8)])
    # 40.6 is 0.6 from 40.0; 41.2 is 0.6 from 40.6; 39.9 is 1.3 from 41.2
    assert [value for _, value in sent] == [40.0, 40.6, 41.2, 39.9]
    assert events.stats()["/motor/temperature"]["unchanged"] == 4


@pytest.mark.parametrize(
    ("old", "new", "deadband", "expected"),
    [
        ({"a": 1.0}, {"a": 1.4}, 0.5, False),
        ({"a": 1.0}, {"a": 1.6}, 0.5, True),
        ({"a": [1, 2]}, {"a": [1, 2, 3]}, 10.0, True),
        ({"a": "x"}, {"a": "y"}, 10.0, True),
        ({"a": True}, {"a": False}, 10.0, True),
        ({"a": {"b": 1}}, {"a": {"c": 1}}, 10.0, True),
        ({"a": 1}, {"a": 1}, 0.0, False),
    ],
)
def test_what_counts_as_a_change(old, new, deadband, expected) -> None:
    assert changed(old, new, deadband) is expected


def log(level: int, logger: str, text: str = "x") -> dict:
    return handle_log(m.Log(level=level, name=logger, msg=text, stamp=m.Time(sec=5)))


def test_rosout_keeps_the_level_and_limits_bursts_per_logger() -> None:
    records = LogRecords("warn", burst=3, window_s=60.0)
    records.observe(log(m.Log.INFO, "nav2.planner"), 0.0)  # below the level
    for i in range(10):  # a burst of ten errors from one logger
        records.observe(log(m.Log.ERROR, "nav2.controller", f"stuck {i}"), 1.0 + i)
    records.observe(log(m.Log.WARN, "lidar"), 2.0)  # another logger is not held back
    records.observe(log(m.Log.ERROR, "phytrace_edge"), 3.0)  # the bridge's own: skipped
    records.observe(log(m.Log.ERROR, "phytrace_edge.rclpy"), 3.0)
    sent = [record for record, _ in records.take()]
    assert [r["message"] for r in sent if r["logger"] == "nav2.controller"] == [
        "stuck 0",
        "stuck 1",
        "stuck 2",
    ]
    assert [r["logger"] for r in sent].count("lidar") == 1
    assert records.counts == {"below_level": 1, "suppressed": 7, "own": 2, "records": 4}
    # a minute later the logger may speak again, and says what was held back
    records.observe(log(m.Log.FATAL, "nav2.controller", "gave up"), 70.0)
    ((record, _),) = records.take()
    assert record["level"] == "fatal" and record["suppressed"] == 7
    assert "suppressed" not in sent[0]


def test_rosout_levels_between_ros_levels_count_as_the_lower() -> None:
    assert log(35, "x")["level"] == "warn"
    assert log(5, "x")["level"] == "debug"
    assert log(m.Log.ERROR, "x")["stamp_ns"] == 5_000_000_000


def test_side_events_are_valid_udm_and_classed() -> None:
    options = BuilderOptions(
        Identity("amr-7", "amr"),
        extra_topics=(ExtraTopic("/motor/temperature", mode="on_change"), ExtraTopic("/tf")),
    )
    builder = UDMBuilder(options)
    builder.add_message("/motor/temperature", m.wire_copy(temperature(50.0)))
    builder.add_message("/tf", m.TFMessage())
    builder.add_message("/not/configured", temperature(1.0))
    builder.add_reading("/rosout", log(m.Log.ERROR, "nav2.bt_navigator", "goal failed"))
    built = builder.side_events(1_795_338_843.0)
    assert [b.event["event_type"] for b in built] == [
        "log.record",
        "telemetry.topic",
        "telemetry.topic",
    ]
    for b in built:
        assert find_violation(b.event) is None, b.event
    topic, tf = built[1].event, built[2].event
    assert topic["type"] == "sensor_msgs/msg/Temperature" and topic["data"]["temperature"] == 50.0
    assert tf["clock"] == "none" and tf["data"] == {"transforms": []}
    assert [b.important for b in built] == [True, True, False]  # log, on_change, sample
    assert builder.side_counts()["/rosout"]["records"] == 1
    assert builder.side_events() == []
