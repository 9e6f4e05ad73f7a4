"""The flight recorder's parts on a clock the test moves: the ring's bounds, the
trigger rules, windows opened, extended, rate-limited and closed, and parts that fit
a request and join back into the window."""

from __future__ import annotations

import orjson
import pytest

from phytrace_edge.config.incident_triggers import incident_triggers
from phytrace_edge.incident.options import IncidentOptions
from phytrace_edge.incident.parts import ClosedIncident, incident_events
from phytrace_edge.incident.recorder import IncidentRecorder
from phytrace_edge.incident.ring import SAMPLE_OVERHEAD_BYTES, WindowRing
from phytrace_edge.incident.triggers import Condition, Trigger, TriggerRules
from phytrace_edge.udm.event import parse_timestamp
from phytrace_edge.udm.schema import check_event
from phytrace_edge.udm.types import UdmIdentity

IDENTITY = UdmIdentity(source_id="amr-7", source_type="amr")
EPOCH = 1_795_000_000.0  # the wall clock at timeline 0


class Clock:
    """A timeline the test moves: monotonic from 0, wall from EPOCH."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        return self.now

    def wall(self) -> float:
        return EPOCH + self.now


def odom(n: int) -> dict[str, object]:
    return {"linear_velocity": {"x_mps": n / 1000, "y_mps": 0.0, "z_mps": 0.0}, "seq": n}


def diagnostics(level: str, name: str = "lidar") -> dict[str, object]:
    return {"statuses": [{"name": name, "level": level, "message": "no data", "hardware_id": ""}]}


def recorder(clock: Clock, **options: object) -> IncidentRecorder:
    return IncidentRecorder(
        IncidentOptions(**options),  # type: ignore[arg-type]
        IDENTITY,
        max_part_bytes=256 * 1024,
        clock=clock,
    )


def run(rec: IncidentRecorder, clock: Clock, until_s: float, rate_hz: float, start_n: int = 0):
    """/odom at ``rate_hz`` from now until ``until_s``; the events closed on the way."""
    built, n = [], start_n
    while clock.now < until_s:
        rec.observe("/odom", odom(n))
        n += 1
        clock.now = round(clock.now + 1 / rate_hz, 9)
        built += rec.take_closed()
    return built, n


def joined(events: list) -> dict[str, list[dict]]:
    samples: dict[str, list[dict]] = {}
    for event in sorted(events, key=lambda e: e["incident"]["part"]):
        for topic, items in event["incident"]["samples"].items():
            samples.setdefault(topic, []).extend(items)
    return samples


def test_the_ring_holds_its_byte_bound_at_demanding_rates() -> None:
    """IMU at 400 Hz and 24 joints at 500 Hz for a minute: far more than 1 MiB; the
    ring never holds more, drops the oldest first and counts each by topic."""
    ring = WindowRing(max_bytes=1024 * 1024)
    imu = {"imu": {"orientation_deg": {"roll": 0.1, "pitch": 0.2, "yaw": 33.3}}, "stamp_ns": 1}
    joints = {"joints": [{"name": f"j{i}", "position": i * 0.01} for i in range(24)]}
    added = {"/imu/data": 0, "/joint_states": 0}
    for tick in range(60 * 2000):  # 2 kHz base: IMU every 5th, joints every 4th
        at = tick / 2000
        if tick % 5 == 0:
            ring.add("/imu/data", imu, at)
            added["/imu/data"] += 1
        if tick % 4 == 0:
            ring.add("/joint_states", joints, at)
            added["/joint_states"] += 1
        assert ring.bytes <= ring.max_bytes
    kept = list(ring.between(0, 60))
    assert len(kept) == len(ring)
    assert sum(len(s.json) + SAMPLE_OVERHEAD_BYTES for s in kept) == ring.bytes
    for topic in added:
        assert ring.dropped[topic] + sum(s.topic == topic for s in kept) == added[topic]
    assert kept[-1].at_s == pytest.approx((60 * 2000 - 4) / 2000)  # the newest stay
    assert [s.at_s for s in kept] == sorted(s.at_s for s in kept)


def test_a_diagnostics_error_records_the_window_around_it_at_full_rate() -> None:
    clock = Clock()
    rec = recorder(clock)
    before, n = run(rec, clock, 60.0, rate_hz=50)
    assert before == []
    rec.observe("/diagnostics", diagnostics("error"))
    built, _ = run(rec, clock, 90.0, rate_hz=50, start_n=n)
    assert [b.important for b in built] == [True] * len(built) and built
    events = [b.event for b in built]
    assert all(check_event(event) for event in events)
    incident = events[0]["incident"]
    assert incident["trigger"]["kind"] == "diagnostics"
    assert incident["trigger"]["level"] == "error"
    assert parse_timestamp(incident["window"]["start"]) == pytest.approx(EPOCH + 30.0)
    assert parse_timestamp(incident["window"]["end"]) == pytest.approx(EPOCH + 70.0)
    samples = joined(events)["/odom"]
    times = [parse_timestamp(s["t"]) - EPOCH for s in samples]
    assert times[0] == pytest.approx(30.0, abs=0.021) and times[-1] == pytest.approx(
        70.0, abs=0.021
    )
    assert len(samples) == pytest.approx(40 * 50, abs=2)  # every message, none thinned
    assert [s["seq"] for s in samples] == list(range(samples[0]["seq"], samples[-1]["seq"] + 1))
    assert samples[10]["linear_velocity"] == odom(samples[10]["seq"])["linear_velocity"]
    assert rec.counts["recorded"] == 1 and rec.counts["opened"] == 1


def test_parts_fit_the_request_limit_and_join_back_into_the_window() -> None:
    clock = Clock()
    rec = IncidentRecorder(IncidentOptions(), IDENTITY, max_part_bytes=64 * 1024, clock=clock)
    _, n = run(rec, clock, 40.0, rate_hz=100)
    rec.mark("bumped a shelf")
    built, _ = run(rec, clock, 60.0, rate_hz=100, start_n=n)
    events = [b.event for b in built]
    assert len(events) > 3
    assert all(len(orjson.dumps(e)) <= 64 * 1024 for e in events)
    assert {e["incident"]["parts"] for e in events} == {len(events)}
    assert [e["incident"]["part"] for e in events] == list(range(1, len(events) + 1))
    assert len({e["incident"]["id"] for e in events}) == 1
    assert len({e["event_id"] for e in events}) == len(events)
    seqs = [s["seq"] for s in joined(events)["/odom"]]
    # [10 s, 50 s] at 100 Hz, both ends: a window closes only once time is past its end
    assert seqs == list(range(1000, 5001))


def test_the_same_incident_gets_the_same_ids() -> None:
    """A bag replayed twice gives the same incident: PhyCloud takes it once."""
    trigger = Trigger("diagnostics", "lidar: no data", 60.0, EPOCH + 60.0, "/diagnostics", "error")
    closed = ClosedIncident(trigger, 30.0, 70.0, EPOCH + 30.0, EPOCH + 70.0, samples=())
    first = incident_events(IDENTITY, closed, 1024 * 1024)
    again = incident_events(IDENTITY, closed, 1024 * 1024)
    assert [e["event_id"] for e in first] == [e["event_id"] for e in again]
    other = incident_events(UdmIdentity(source_id="amr-8", source_type="amr"), closed, 1 << 20)
    assert other[0]["event_id"] != first[0]["event_id"]
    assert first[0]["incident"]["samples"] == {} and check_event(first[0])


def test_triggers_inside_a_window_extend_it_up_to_its_maximum() -> None:
    clock = Clock()
    rec = recorder(clock, max_s=25.0)
    _, n = run(rec, clock, 40.0, rate_hz=10)
    assert rec.mark("first").outcome == "opened"
    _, n = run(rec, clock, 48.0, rate_hz=10, start_n=n)
    assert rec.mark("second").outcome == "extended"  # ends at 58 now
    _, n = run(rec, clock, 57.0, rate_hz=10, start_n=n)
    assert rec.mark("third").outcome == "extended"  # would end at 67: capped at 65
    built, _ = run(rec, clock, 80.0, rate_hz=10, start_n=n)
    incident = built[0].event["incident"]
    assert parse_timestamp(incident["window"]["end"]) == pytest.approx(EPOCH + 65.0)
    assert incident["triggers"] == 3 and incident["trigger"]["message"] == "first"
    assert rec.counts["extended"] == 2 and rec.counts["recorded"] == 1


def test_a_storm_of_triggers_is_bounded_and_counted() -> None:
    """A flapping status for an hour: incidents at most INCIDENT_MAX_PER_HOUR, every
    other trigger counted as extending one or as rate-limited."""
    clock = Clock()
    rec = recorder(clock, max_per_hour=4, before_s=2.0, after_s=1.0)
    built = []
    for second in range(3600):
        clock.now = float(second)
        rec.observe("/diagnostics", diagnostics("error" if second % 2 else "ok"))
        built += rec.take_closed()
    clock.now = 3601.0
    built += rec.take_closed()
    ids = {b.event["incident"]["id"] for b in built}
    assert len(ids) == rec.counts["recorded"] == 4
    counts = rec.counts
    assert counts["triggers"] == 1800
    assert counts["opened"] + counts["extended"] + counts["rate_limited"] == 1800
    assert counts["rate_limited"] >= 1790


def test_a_status_that_stays_in_error_is_one_trigger() -> None:
    rules = TriggerRules()
    fired = [len(rules.observe("/diagnostics", diagnostics("error"), t, t)) for t in range(5)]
    assert fired == [1, 0, 0, 0, 0]
    assert rules.observe("/diagnostics", diagnostics("ok"), 5, 5) == []
    assert len(rules.observe("/diagnostics", diagnostics("stale"), 6, 6)) == 1
    assert rules.observe("/diagnostics", diagnostics("warn", name="motor"), 7, 7) == []
    warn = TriggerRules(diagnostics_level="warn")
    assert len(warn.observe("/diagnostics", diagnostics("warn", name="motor"), 7, 7)) == 1


def test_rosout_errors_trigger_and_lesser_records_do_not() -> None:
    rules = TriggerRules()
    record = {"level": "error", "logger": "nav2", "message": "collision ahead"}
    (trigger,) = rules.observe("/rosout", record, 1.0, EPOCH + 1)
    assert (trigger.kind, trigger.level, trigger.message) == (
        "rosout",
        "error",
        "nav2: collision ahead",
    )
    assert rules.observe("/rosout", {**record, "level": "warn"}, 2.0, EPOCH + 2) == []
    assert TriggerRules(rosout_level=None).observe("/rosout", record, 3.0, EPOCH + 3) == []


def test_a_topic_condition_fires_when_it_becomes_true() -> None:
    (estop, failed) = incident_triggers(
        "/estop data == true; /delivery/status payload.delivery_state == failed"
    )
    assert estop == Condition("/estop", ("data",), "==", True)
    assert failed.value == "failed"
    rules = TriggerRules(conditions=(estop, failed))
    seen = [len(rules.observe("/estop", {"data": v}, t, t)) for t, v in enumerate([0, 1, 1, 0, 1])]
    assert seen == [0, 1, 0, 0, 1]
    status = {"payload": {"delivery_state": "failed"}}
    (trigger,) = rules.observe("/delivery/status", status, 9, 9)
    assert trigger.kind == "topic" and trigger.topic == "/delivery/status"
    assert rules.observe("/delivery/status", {"payload": {}}, 10, 10) == []


@pytest.mark.parametrize(
    "text",
    ["estop data == true", "/estop == true", "/estop data ~ 1", "/estop data == [1]", 5],
)
def test_a_bad_condition_is_refused(text: object) -> None:
    with pytest.raises(ValueError, match="TOPIC FIELD OP VALUE"):
        incident_triggers(text)


def test_a_stop_keeps_the_open_incident_cut_short() -> None:
    clock = Clock()
    rec = recorder(clock)
    _, n = run(rec, clock, 35.0, rate_hz=20)
    rec.mark("operator saw a wobble")
    run(rec, clock, 38.0, rate_hz=20, start_n=n)
    (built,) = rec.close_now()
    incident = built.event["incident"]
    assert incident["cut_short"] is True and incident["trigger"]["kind"] == "manual"
    assert parse_timestamp(incident["window"]["end"]) == pytest.approx(EPOCH + 38.0)
    assert rec.counts["cut_short"] == 1 and rec.close_now() == []


def test_an_incident_stamped_on_an_unsynchronized_clock_says_so() -> None:
    """As every event: a later clock step repairs what it says (docs/udm.md, "Time")."""
    clock, synchronized = Clock(), [False]
    rec = IncidentRecorder(
        IncidentOptions(), IDENTITY, 1 << 20, clock, unsynchronized=lambda: not synchronized[0]
    )
    _, n = run(rec, clock, 5.0, rate_hz=10)
    rec.mark("first")
    built, n = run(rec, clock, 20.0, rate_hz=10, start_n=n)
    assert [b.event.get("wall_clock") for b in built] == [{"synchronized": False}]
    synchronized[0] = True
    rec.mark("second")
    built, _ = run(rec, clock, 40.0, rate_hz=10, start_n=n)
    assert [b.event.get("wall_clock") for b in built] == [None]
    assert all(check_event(b.event) for b in built)


def test_nothing_is_kept_or_marked_while_recording_is_off() -> None:
    clock = Clock()
    rec = recorder(clock, enabled=False)
    run(rec, clock, 5.0, rate_hz=50)
    assert rec.mark("x").outcome == "off"
    assert rec.figures()["buffer_samples"] == 0 and rec.close_now() == []
