"""Messages from plain data (``tests.ros.known``): nested dicts and lists set on the
message classes of real rclpy or the mock, which share rosidl's field types."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def message_class(type_name: str) -> type:
    """``sensor_msgs/msg/Imu`` or ``sensor_msgs/Imu`` -> the class."""
    package, *_, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)  # type: ignore[no-any-return]


def fill(msg: Any, fields: dict[str, Any], classes: Callable[[str], type] = message_class) -> Any:
    """Set ``fields`` on ``msg`` (rosidl field types decide: a ``byte`` is one byte, a
    sequence of messages is built element by element, its class found by ``classes``);
    returns ``msg``."""
    types = msg.get_fields_and_field_types()
    for name, value in fields.items():
        kind = types[name]
        if isinstance(value, dict):
            fill(getattr(msg, name), value, classes)
        elif kind.startswith("sequence<") and "/" in kind:
            element = classes(kind[len("sequence<") : -1])
            setattr(msg, name, [fill(element(), item) for item in value])
        elif kind == "octet":
            setattr(msg, name, bytes([value]))
        else:
            setattr(msg, name, value)
    return msg
