"""One message, three field-type conventions: rclpy (the mock), rosbags, and DDS-like.

Tests build a message once with the mock classes (rclpy's types: ``bytes`` levels,
``array.array`` sequences, numpy fixed arrays), pass it through the middleware as a
subscriber receives it (float32 fields become the nearest float32), and convert it:

- ``rosbags``: the real rosbags Jazzy type store classes (ints for bytes and uint8,
  numpy arrays for every numeric array).
- ``dds``: plain objects with Python lists and ints, as Cyclone DDS IDL samples carry.
"""

from __future__ import annotations

import array
from types import SimpleNamespace
from typing import Any

import numpy as np

from phytrace_edge.sim import recorder
from phytrace_edge.sim.mock_ros.messages import Message, wire_copy

FLAVOURS = ("rclpy", "rosbags", "dds")


_STORE: Any = None


def to_rosbags(msg: Message) -> Any:
    global _STORE
    if _STORE is None:
        from rosbags.typesys import Stores, get_typestore

        _STORE = get_typestore(Stores.ROS2_JAZZY)
    return recorder.to_rosbags(msg, _STORE)


def to_dds(msg: Any) -> Any:
    if isinstance(msg, Message):
        return SimpleNamespace(**{n: to_dds(getattr(msg, n)) for n in msg._fields_and_field_types})
    if isinstance(msg, bytes):
        return msg[0]
    if isinstance(msg, (array.array, np.ndarray)):
        return [float(v) for v in msg]
    if isinstance(msg, list):
        return [to_dds(item) for item in msg]
    return msg


def as_flavour(msg: Message, flavour: str) -> Any:
    msg = wire_copy(msg)
    if flavour == "rclpy":
        return msg
    if flavour == "rosbags":
        return to_rosbags(msg)
    return to_dds(msg)
