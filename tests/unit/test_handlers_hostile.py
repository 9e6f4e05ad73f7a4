"""Property tests: handlers on hostile input never crash and never emit NaN, inf or None,
and whatever they produce still builds a schema-valid event."""

from __future__ import annotations

import json
from types import SimpleNamespace as NS
from typing import Any, get_type_hints

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.topics import TOPICS
from phytrace_edge.udm.schema import find_violation
from tests.conftest import FakeClock, non_finite_values
from tests.unit.test_topic_table import undeclared_keys

hostile_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0]),
)
wrong_type = st.one_of(
    st.none(),
    st.text(max_size=5),
    st.booleans(),
    st.binary(max_size=3),
    st.lists(st.integers(), max_size=2),
)
number = st.one_of(hostile_float, st.integers(-(2**70), 2**70), wrong_type)


def float32_array(size: int, value: float) -> np.ndarray:
    with np.errstate(over="ignore"):  # values beyond float32 become inf, as on the wire
        return np.full(size, value).astype(np.float32)


arrays = st.one_of(
    st.lists(hostile_float, max_size=50),
    st.builds(float32_array, st.integers(0, 5_000), hostile_float),
    st.builds(lambda xs: np.array(xs, dtype=np.float64), st.lists(hostile_float, max_size=20)),
    st.just([]),
    wrong_type,
)
stamp = st.builds(
    NS,
    sec=st.one_of(st.integers(-(2**31), 2**31), wrong_type),
    nanosec=st.one_of(st.integers(0, 2**32), wrong_type),
)
header = st.builds(NS, stamp=stamp, frame_id=st.one_of(st.text(max_size=300), wrong_type))
vector = st.builds(NS, x=number, y=number, z=number)
quaternion = st.builds(NS, x=number, y=number, z=number, w=number)
level = st.one_of(st.binary(min_size=0, max_size=2), st.integers(-5, 300), wrong_type)

MESSAGES = {
    "/odom": st.builds(
        NS,
        header=header,
        pose=st.builds(NS, pose=st.builds(NS, position=vector, orientation=quaternion)),
        twist=st.builds(NS, twist=st.builds(NS, linear=vector, angular=vector)),
    ),
    "/battery_state": st.builds(
        NS,
        header=header,
        voltage=number,
        current=number,
        percentage=number,
        temperature=number,
        charge=number,
        capacity=number,
        power_supply_status=st.one_of(st.integers(-3, 300), wrong_type),
        power_supply_health=st.one_of(st.integers(-3, 300), wrong_type),
        present=wrong_type,
        cell_voltage=arrays,
    ),
    "/scan": st.builds(
        NS,
        header=header,
        angle_min=number,
        angle_max=number,
        angle_increment=number,
        range_min=number,
        range_max=number,
        ranges=arrays,
    ),
    "/imu/data": st.builds(
        NS,
        header=header,
        orientation=quaternion,
        orientation_covariance=arrays,
        angular_velocity=vector,
        linear_acceleration=vector,
    ),
    "/cmd_vel": st.builds(NS, linear=vector, angular=vector),
    "/gps/fix": st.builds(
        NS,
        header=header,
        status=st.builds(NS, status=st.one_of(st.integers(-3, 3), wrong_type)),
        latitude=number,
        longitude=number,
        altitude=number,
        position_covariance=arrays,
        position_covariance_type=st.one_of(st.integers(0, 3), wrong_type),
    ),
    "/diagnostics": st.builds(
        NS,
        header=header,
        status=st.lists(
            st.builds(
                NS,
                level=level,
                name=st.one_of(st.text(max_size=300), wrong_type),
                message=st.one_of(st.text(), wrong_type),
                hardware_id=wrong_type,
            ),
            max_size=5,
        ),
    ),
    "/goal_pose": st.builds(
        NS, header=header, pose=st.builds(NS, position=vector, orientation=quaternion)
    ),
    "/joint_states": st.builds(
        NS,
        header=header,
        name=st.one_of(st.lists(st.text(max_size=10), max_size=300), wrong_type),
        position=arrays,
        velocity=arrays,
        effort=arrays,
    ),
    "/delivery/status": st.builds(
        NS,
        data=st.one_of(
            st.text(max_size=50),
            st.dictionaries(
                st.sampled_from(
                    ["order_id", "state", "task_status", "robot_state", "destination", "x"]
                ),
                st.one_of(
                    st.text(max_size=300),
                    st.integers(),
                    st.floats(),
                    st.none(),
                    st.lists(st.integers(), max_size=2),
                ),
            ).map(json.dumps),  # stdlib: also writes integers orjson cannot read
            wrong_type,
        ),
    ),
}


def _handle(topic: str, msg: Any) -> dict | None:
    spec = next(spec for spec in TOPICS if spec.name == topic)
    try:
        reading: dict[str, Any] = dict(spec.handler(msg))
    except MalformedMessage:
        return None
    assert undeclared_keys(reading, get_type_hints(spec.handler)["return"]) == []
    reading.pop("rejected_fields", None)
    return reading


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_every_handler_survives_hostile_input_and_events_stay_valid(data: st.DataObject) -> None:
    builder = UDMBuilder(
        BuilderOptions(Identity("bot", "amr"), stale_after_s=5.0), clock=FakeClock()
    )
    for topic, strategy in MESSAGES.items():
        reading = _handle(topic, data.draw(strategy, label=topic))
        if reading is None:
            continue
        assert non_finite_values(reading) == [], (topic, reading)
        builder.add_reading(topic, reading)
    event = builder.build().event
    assert non_finite_values(event) == []
    assert find_violation(event) is None, find_violation(event)
