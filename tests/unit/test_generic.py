"""Any message -> JSON (``ingest.generic``): known values give known JSON in every
flavour the bridge reads (rclpy, rosbags, Cyclone DDS samples that went through CDR),
and hostile values never break it."""

from __future__ import annotations

import array
import json
import math
from typing import Any

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phytrace_edge.ingest.generic import (
    message_data,
    message_type_name,
    rosbags_field_types,
    rosidl_field_types,
)
from phytrace_edge.sim.mock_ros import messages as m
from tests.flavours import to_rosbags

STAMP = m.Time(sec=1_795_338_843, nanosec=250_000_000)
HEADER = {"stamp": {"sec": 1_795_338_843, "nanosec": 250_000_000}, "frame_id": "left_motor"}


def temperature() -> m.Message:
    return m.Temperature(
        header=m.Header(stamp=STAMP, frame_id="left_motor"), temperature=61.5, variance=0.25
    )


def tf_message() -> m.Message:
    transform = m.Transform(
        translation=m.Vector3(x=1.25, y=-0.5, z=0.0),
        rotation=m.Quaternion(x=0.0, y=0.0, z=0.7071067811865476, w=0.7071067811865476),
    )
    stamped = m.TransformStamped(
        header=m.Header(stamp=STAMP, frame_id="odom"),
        child_frame_id="base_link",
        transform=transform,
    )
    return m.TFMessage(transforms=[stamped])


def float32_array() -> m.Message:
    layout = m.MultiArrayLayout(
        dim=[m.MultiArrayDimension(label="cells", size=3, stride=3)], data_offset=0
    )
    return m.Float32MultiArray(layout=layout, data=[0.12, 3.3, math.nan])


def compressed_image() -> m.Message:
    return m.CompressedImage(
        header=m.Header(stamp=STAMP, frame_id="left_motor"), format="jpeg", data=[1, 2, 3, 255]
    )


KNOWN = [
    (
        temperature,
        {"header": HEADER, "temperature": 61.5, "variance": 0.25},
    ),
    (
        tf_message,
        {
            "transforms": [
                {
                    "header": {"stamp": HEADER["stamp"], "frame_id": "odom"},
                    "child_frame_id": "base_link",
                    "transform": {
                        "translation": {"x": 1.25, "y": -0.5, "z": 0.0},
                        "rotation": {
                            "x": 0.0,
                            "y": 0.0,
                            "z": 0.7071067811865476,
                            "w": 0.7071067811865476,
                        },
                    },
                }
            ]
        },
    ),
    (
        # float32 data: the shortest decimals of the float32 values; NaN is null
        float32_array,
        {
            "layout": {"dim": [{"label": "cells", "size": 3, "stride": 3}], "data_offset": 0},
            "data": [0.12, 3.3, None],
        },
    ),
    (
        compressed_image,
        {"header": HEADER, "format": "jpeg", "data": "AQID/w=="},
    ),
]


def to_idl(msg: m.Message) -> Any:
    """The mock message as a Cyclone DDS sample of the type the dds input makes, after
    a trip through CDR bytes (what a DataReader hands over)."""
    from phytrace_edge.ingest.sources.dds_dynamic import idl_type

    def value(v: Any) -> Any:
        if isinstance(v, m.Message):
            return build(v)
        if isinstance(v, bytes):
            return v[0]
        if isinstance(v, (array.array, np.ndarray)):
            return v.tolist()
        if isinstance(v, list):
            return [value(item) for item in v]
        return v

    def build(msg: m.Message) -> Any:
        fields = {name: value(getattr(msg, name)) for name in msg._fields_and_field_types}
        return idl_type(msg._type)(**fields)

    sample = build(msg)
    return type(sample).deserialize(sample.serialize())


def converted(msg: m.Message, flavour: str, max_array: int = 256) -> dict[str, Any]:
    msg = m.wire_copy(msg)
    if flavour == "rclpy":
        return message_data(msg, rosidl_field_types, max_array)
    from phytrace_edge.ingest.sources.dds_dynamic import fielddefs

    field_types = rosbags_field_types(fielddefs())
    other = to_rosbags(msg) if flavour == "rosbags" else to_idl(msg)
    assert message_type_name(other) == msg._type
    return message_data(other, field_types, max_array)


@pytest.mark.parametrize("flavour", ["rclpy", "rosbags", "dds"])
@pytest.mark.parametrize(("make", "expected"), KNOWN, ids=[k[0].__name__ for k in KNOWN])
def test_known_messages_give_known_json(make, expected, flavour: str) -> None:
    assert converted(make(), flavour) == expected


@pytest.mark.parametrize("flavour", ["rclpy", "rosbags", "dds"])
def test_long_arrays_and_blobs_become_len_and_head(flavour: str) -> None:
    msg = m.CompressedImage(format="png", data=list(range(200)))
    data = converted(msg, flavour, max_array=4)
    assert data["data"] == {"len": 200, "head": "AAECAw=="}
    cells = m.Float32MultiArray(data=[float(i) for i in range(10)])
    assert converted(cells, flavour, max_array=3)["data"] == {"len": 10, "head": [0.0, 1.0, 2.0]}


def test_a_nan_scalar_is_left_out_and_rclpy_byte_arrays_are_base64() -> None:
    msg = m.Temperature(temperature=math.inf, variance=math.nan)
    assert set(message_data(msg, rosidl_field_types, 256)) == {"header"}
    blob = m.ByteMultiArray(data=[b"\x00", b"\xff"])
    assert message_data(blob, rosidl_field_types, 256)["data"] == "AP8="


def test_type_names_of_each_flavour() -> None:
    assert message_type_name(temperature()) == "sensor_msgs/msg/Temperature"
    fake_rclpy = type("Temperature", (), {"__module__": "sensor_msgs.msg._temperature"})()
    assert message_type_name(fake_rclpy) == "sensor_msgs/msg/Temperature"


hostile_floats = st.floats(allow_nan=True, allow_infinity=True, width=64)


def refuse_constant(literal: str) -> None:
    raise AssertionError(f"{literal} in the JSON: not strict JSON")


@settings(max_examples=200, deadline=None)
@given(
    values=st.lists(hostile_floats, max_size=40),
    temperature=hostile_floats,
    label=st.text(max_size=3000),
    blob=st.binary(max_size=600),
    max_array=st.integers(1, 300),
)
def test_hostile_values_always_give_strict_json(values, temperature, label, blob, max_array):
    """Any float (NaN, inf, beyond float32), any text and any bytes: the result is
    JSON without NaN or infinity, arrays and text within their bounds."""
    with np.errstate(over="ignore"):  # beyond float32 becomes inf, as on the wire
        data32 = np.array(values, dtype=np.float64).astype(np.float32)
    cells = m.Float32MultiArray(
        layout=m.MultiArrayLayout(dim=[m.MultiArrayDimension(label=label)]),
        data=array.array("f", data32),
    )
    sensor = m.Temperature(temperature=temperature, variance=0.0)
    image = m.CompressedImage(format=label, data=list(blob))
    from phytrace_edge.ingest.sources.dds_dynamic import fielddefs

    from_bag = rosbags_field_types(fielddefs())
    for msg in (cells, sensor, image):
        data = message_data(msg, rosidl_field_types, max_array)
        assert message_data(to_rosbags(msg), from_bag, max_array) == data
        text = orjson.dumps(data)
        # strict JSON: no NaN or Infinity literal (a label may well read "Infinity")
        json.loads(text, parse_constant=refuse_constant)
        for value in data.values():
            if isinstance(value, dict) and "len" in value:
                assert len(value["head"]) <= max(max_array, 4 * ((max_array + 2) // 3))
    label_out = message_data(cells, rosidl_field_types, max_array)["layout"]["dim"][0]["label"]
    assert len(label_out) <= 2048
