"""Text from the robot is made safe where the handlers and the generic converter take
it (issue 31): a lone surrogate anywhere in a message becomes U+FFFD, the message is
kept, its event encodes with orjson (as the queue writer does), and the topic counts
``text_repaired``."""

from __future__ import annotations

import json
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.ingest import handlers as h
from phytrace_edge.ingest import robot_status, rosout
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.topics import ExtraTopic
from phytrace_edge.sim.mock_ros import messages as m
from phytrace_edge.udm.schema import find_violation
from tests.conftest import FakeClock
from tests.flavours import as_flavour

FFFD = "\ufffd"
BROKEN = "x\ud800"  # what a JSON escape or surrogateescape leaves in a Python str
REPAIRED = f"x{FFFD}"


class Bridge:
    """The dispatcher and the builder, wired as the pipeline wires them."""

    def __init__(self, *extras: ExtraTopic) -> None:
        self.clock = FakeClock()
        options = BuilderOptions(
            Identity("bot-1", "amr"),
            stale_after_s=5.0,
            extra_topics=extras,
            rosout_min_level="info",
        )
        self.builder = UDMBuilder(options, clock=self.clock)
        self.dispatcher = Dispatcher(self.builder.add_reading, self.builder.add_message)

    def events(self) -> list[dict[str, Any]]:
        """The side events and the periodic event of one tick, each encoded by orjson
        and checked against the schema."""
        self.clock.advance(1.0)
        events = [built.event for built in self.builder.side_events()]
        events.append(self.builder.build().event)
        for event in events:
            orjson.dumps(event)  # what the queue writer does: raises on a lone surrogate
            assert find_violation(event) is None, event
        return events

    def rejected(self, topic: str) -> dict[str, int]:
        return {r: n for (t, r), n in self.dispatcher.rejected.items() if t == topic}


def delivery(document_text: str) -> m.Message:
    return m.String(data=document_text)


def test_an_escaped_lone_surrogate_in_delivery_status_is_repaired_and_counted() -> None:
    bridge = Bridge()
    text = '{"order_id": "o-\\ud800", "state": "en_route", "destination": "dock \\udc01 7"}'
    assert "\ud800" in json.loads(text)["order_id"]  # valid JSON, not valid UTF-8

    bridge.dispatcher.on_message("/delivery/status", delivery(text))

    (event,) = bridge.events()
    assert event["payload"]["order_id"] == f"o-{FFFD}"
    assert event["payload"]["destination"] == f"dock {FFFD} 7"
    assert event["operational"]["task"]["task_id"] == f"o-{FFFD}"
    assert bridge.rejected("/delivery/status") == {"text_repaired": 1}  # one message
    assert bridge.dispatcher.received["/delivery/status"] == 1


def test_a_lone_surrogate_in_a_delivery_status_key_is_repaired_and_counted() -> None:
    bridge = Bridge()
    text = '{"order_id": "o-1", "state": "loading", "\\udfff": {"\\ud800x": ["\\udc00"]}}'

    reading = robot_status.handle_delivery_status(delivery(text))
    assert reading["text_repaired"] == 3  # the key, the nested key, the nested value
    bridge.dispatcher.on_message("/delivery/status", delivery(text))

    (event,) = bridge.events()
    assert event["payload"] == {
        "order_id": "o-1",
        "delivery_state": "loading",
        "sources": event["payload"]["sources"],
    }
    assert bridge.rejected("/delivery/status") == {"text_repaired": 1}


@pytest.mark.parametrize(
    ("data", "expected_state"),
    [
        ('{"state": "' + BROKEN + '"}', REPAIRED),  # a str decoded with surrogateescape
        (b'{"state": "s\xff4"}', f"s{FFFD}4"),  # bytes that are not UTF-8
        ('{"state": "\\ud83d\\ude00"}', "😀"),  # an escaped pair is a character: fine
    ],
)
def test_delivery_status_text_that_is_not_utf8(data: Any, expected_state: str) -> None:
    msg = type("Msg", (), {"data": data})()  # any flavour's String: str, or bytes
    reading = robot_status.handle_delivery_status(msg)
    assert reading["payload"]["delivery_state"] == expected_state
    assert reading.get("text_repaired", 0) == (0 if expected_state == "😀" else 1)


def test_fine_text_is_not_counted(flavour: str) -> None:
    bridge = Bridge()
    bridge.dispatcher.on_message(
        "/delivery/status", delivery('{"order_id": "o-1", "destination": "Z\\u00fcrich"}')
    )
    status_msg = m.DiagnosticStatus(level=b"\x01", name="motor", message="hot", hardware_id="m1")
    bridge.dispatcher.on_message(
        "/diagnostics",
        as_flavour(m.DiagnosticArray(header=m.Header(), status=[status_msg]), flavour),
    )
    events = bridge.events()
    assert events[-1]["payload"]["destination"] == "Zürich"
    assert bridge.dispatcher.rejected == {}


def test_a_frame_id_is_repaired_in_every_flavour(flavour: str) -> None:
    bridge = Bridge()
    msg = m.Odometry(header=m.Header(stamp=m.Time(sec=1, nanosec=0), frame_id=BROKEN))

    reading = h.handle_odometry(as_flavour(msg, flavour))
    assert reading["frame_id"] == REPAIRED and reading["local"]["coordinate_frame"] == REPAIRED
    assert reading["text_repaired"] == 1
    bridge.dispatcher.on_message("/odom", as_flavour(msg, flavour))

    (event,) = bridge.events()
    assert event["location"]["local"]["coordinate_frame"] == REPAIRED
    assert bridge.rejected("/odom") == {"text_repaired": 1}


def test_diagnostics_names_messages_and_hardware_ids_are_repaired(flavour: str) -> None:
    bridge = Bridge()
    statuses = [
        m.DiagnosticStatus(level=b"\x02", name=BROKEN, message=BROKEN, hardware_id=BROKEN),
        m.DiagnosticStatus(level=b"\x01", name="fine", message="ok"),
    ]
    msg = m.DiagnosticArray(header=m.Header(frame_id=BROKEN), status=statuses)

    reading = robot_status.handle_diagnostic_array(as_flavour(msg, flavour))
    assert reading["text_repaired"] == 4  # the frame id and three fields of one status
    bridge.dispatcher.on_message("/diagnostics", as_flavour(msg, flavour))

    (event,) = bridge.events()
    errors = {e["name"]: e for e in event["operational"]["errors"]}
    assert errors[REPAIRED]["message"] == REPAIRED and errors[REPAIRED]["hardware_id"] == REPAIRED
    assert bridge.rejected("/diagnostics") == {"text_repaired": 1}  # messages, not strings


def test_joint_names_are_repaired(flavour: str) -> None:
    msg = m.JointState(header=m.Header(), name=[BROKEN, "wheel", "\udfff"], position=[0.0] * 3)
    reading = h.handle_joint_state(as_flavour(msg, flavour))
    assert [j["name"] for j in reading["joints"]] == [REPAIRED, "wheel", FFFD]
    assert reading["text_repaired"] == 2


def test_ros_log_records_are_repaired() -> None:
    bridge = Bridge()
    record = m.Log(level=m.Log.ERROR, name=BROKEN, msg="goal \udcff failed", file=BROKEN)
    record.function = BROKEN

    reading = rosout.handle_log(record)
    assert reading["logger"] == REPAIRED and reading["message"] == f"goal {FFFD} failed"
    assert reading["text_repaired"] == 4
    bridge.dispatcher.on_message("/rosout", record)

    log_event, _ = bridge.events()
    assert log_event["event_type"] == "log.record" and log_event["file"] == REPAIRED
    assert bridge.rejected("/rosout") == {"text_repaired": 1}


def test_extra_topics_are_repaired_by_the_generic_converter() -> None:
    bridge = Bridge(ExtraTopic("/diagnostics_agg", rate_hz=10.0))
    values = [m.KeyValue(key=BROKEN, value="ok"), m.KeyValue(key="t", value="\ud800\ud800")]
    status_msg = m.DiagnosticStatus(level=b"\x00", name="fine", values=values)
    msg = m.DiagnosticArray(header=m.Header(frame_id=BROKEN), status=[status_msg])

    bridge.dispatcher.on_message("/diagnostics_agg", m.wire_copy(msg))

    topic_event, _ = bridge.events()
    data = topic_event["data"]
    assert data["header"]["frame_id"] == REPAIRED
    assert data["status"][0]["values"] == [
        {"key": REPAIRED, "value": "ok"},
        {"key": "t", "value": FFFD * 2},
    ]
    assert bridge.builder.side_counts()["/diagnostics_agg"] == {"events": 1, "text_repaired": 1}


# hypothesis leaves surrogates out of its characters: they are added here
ANY_TEXT = st.text(
    alphabet=st.one_of(st.characters(), st.integers(0xD800, 0xDFFF).map(chr)), max_size=300
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    frame=ANY_TEXT,
    name=ANY_TEXT,
    message=ANY_TEXT,
    joint=ANY_TEXT,
    state=ANY_TEXT,
    key=ANY_TEXT,
    logger=ANY_TEXT.filter(bool),
)
def test_any_text_in_any_field_gives_events_orjson_encodes(
    frame: str, name: str, message: str, joint: str, state: str, key: str, logger: str
) -> None:
    bridge = Bridge(ExtraTopic("/joints_raw", rate_hz=10.0))
    header = m.Header(stamp=m.Time(sec=1, nanosec=0), frame_id=frame)
    diagnostic = m.DiagnosticStatus(level=b"\x02", name=name, message=message, hardware_id=key)
    joints = m.JointState(header=header, name=[joint], position=[0.5])
    document = json.dumps({"order_id": key, "state": state, key: state})  # \\uXXXX escapes
    for topic, msg in [
        ("/odom", m.Odometry(header=header)),
        ("/diagnostics", m.DiagnosticArray(header=header, status=[diagnostic])),
        ("/joint_states", joints),
        ("/joints_raw", joints),
        ("/goal_pose", m.PoseStamped(header=header)),
        ("/delivery/status", m.String(data=document)),
        ("/rosout", m.Log(level=m.Log.WARN, name=logger, msg=message, file=name)),
    ]:
        bridge.dispatcher.on_message(topic, msg)
    bridge.events()  # each encodes with orjson and is valid UDM
    assert not any(reason == "handler_error" for _, reason in bridge.dispatcher.rejected)


def test_undecodable_messages_are_received_rejected_and_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    bridge = Bridge()
    with caplog.at_level("WARNING", logger="phytrace_edge.ingest.dispatch"):
        for _ in range(3):
            bridge.dispatcher.on_unreadable("/delivery/status", "undecodable", "UnicodeDecodeError")
    assert bridge.dispatcher.received["/delivery/status"] == 3
    assert bridge.rejected("/delivery/status") == {"undecodable": 3}
    (record,) = caplog.records  # at most one a minute per topic and reason
    assert "undecodable, 1 so far" in record.getMessage()


def test_status_tells_repaired_text_from_rejects() -> None:
    from phytrace_edge.cli.status import topic_notes

    reasons = {"text_repaired": 2, "undecodable": 1}
    assert topic_notes({"rejected": reasons}) == ["1 rejected", "2 with text repaired"]
    assert topic_notes({"rejected": {"text_repaired": 1}}) == ["1 with text repaired"]
    extra = {"rejected": {}, "events": 4, "text_repaired": 3}
    assert topic_notes(extra) == ["3 with text repaired", "4 events"]
