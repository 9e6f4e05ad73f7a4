"""The machinery of the mock message classes: field types as real rclpy gives them.

Each class declares ``_fields_and_field_types`` exactly as rosidl_generator_py does,
and the setters convert and check values the way the generated code does:

- ``float`` (float32) / ``double`` -> Python float; ints of any width -> int
- ``octet`` (the ROS ``byte`` type) -> ``bytes`` of length 1, e.g. ``b'\\x02'``
- numeric sequences -> ``array.array`` of the matching typecode (``sequence<float>`` ->
  ``array('f')``, ``sequence<uint8>`` -> ``array('B')``, ...); ``sequence<octet>`` (the
  ROS ``byte[]``) -> a ``list`` of one-byte ``bytes``
- ``double[N]`` (fixed size) -> ``numpy.ndarray`` of float64 and length N
- ``sequence<string>`` and sequences of messages -> ``list``

So a handler that works on these objects works on a real rclpy subscriber's messages.
"""

from __future__ import annotations

import array
import math
import re
import struct
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

_INT_RANGES = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
_FLOAT32_MAX = 3.402823466e38
_ARRAY_TYPECODES = {
    "float": "f",
    "double": "d",
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
}
_FIXED = re.compile(r"^(\w+)\[(\d+)\]$")
_SEQUENCE = re.compile(r"^sequence<(.+)>$")

MESSAGE_TYPES: dict[str, type[Message]] = {}


def _check_float(name: str, kind: str, value: Any) -> float:
    if not isinstance(value, float):
        raise AssertionError(f"The '{name}' field must be of type 'float'")
    out_of_range = value < -_FLOAT32_MAX or value > _FLOAT32_MAX
    if kind == "float" and out_of_range and not math.isinf(value):
        raise AssertionError(f"The '{name}' field must be a float in float32 range")
    return value


def _convert(name: str, kind: str, value: Any) -> Any:
    """Check and convert ``value`` for a field of ROS IDL type ``kind``."""
    if kind in ("float", "double"):
        return _check_float(name, kind, value)
    if kind in _INT_RANGES:
        low, high = _INT_RANGES[kind]
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise AssertionError(f"The '{name}' field must be an integer in [{low}, {high}]")
        return value
    if kind == "boolean":
        if not isinstance(value, bool):
            raise AssertionError(f"The '{name}' field must be of type 'bool'")
        return value
    if kind == "octet":
        if not isinstance(value, bytes) or len(value) != 1:
            raise AssertionError(f"The '{name}' field must be of type 'bytes' of length 1")
        return value
    if kind == "string":
        if not isinstance(value, str):
            raise AssertionError(f"The '{name}' field must be of type 'str'")
        return value
    fixed = _FIXED.match(kind)
    if fixed:
        size = int(fixed.group(2))
        result = np.array(value, dtype=np.float64)
        if result.shape != (size,):
            raise AssertionError(f"The '{name}' field must be a sequence of {size} floats")
        return result
    sequence = _SEQUENCE.match(kind)
    if sequence:
        item = sequence.group(1)
        if item in _ARRAY_TYPECODES:
            code = _ARRAY_TYPECODES[item]
            if isinstance(value, array.array) and value.typecode == code:
                return value
            return array.array(code, [_convert(name, item, v) for v in value])
        return [_convert(name, item, v) for v in value]
    message_type = MESSAGE_TYPES[_full_name(kind)]
    if not isinstance(value, message_type):
        raise AssertionError(f"The '{name}' field must be a sub message of type '{kind}'")
    return value


def _default(kind: str) -> Any:
    if kind in ("float", "double"):
        return 0.0
    if kind in _INT_RANGES:
        return 0
    if kind == "boolean":
        return False
    if kind == "octet":
        return b"\x00"
    if kind == "string":
        return ""
    fixed = _FIXED.match(kind)
    if fixed:
        return np.zeros(int(fixed.group(2)), dtype=np.float64)
    sequence = _SEQUENCE.match(kind)
    if sequence:
        item = sequence.group(1)
        return array.array(_ARRAY_TYPECODES[item]) if item in _ARRAY_TYPECODES else []
    return MESSAGE_TYPES[_full_name(kind)]()


def _full_name(kind: str) -> str:
    package, name = kind.split("/")[0], kind.split("/")[-1]
    return f"{package}/msg/{name}"


class Message:
    """Base of the mock message classes (rosidl_generator_py's behaviour)."""

    _type: ClassVar[str]
    _fields_and_field_types: ClassVar[dict[str, str]]
    _field_defaults: ClassVar[dict[str, Any]] = {}

    if TYPE_CHECKING:  # fields are declared per class in _fields_and_field_types

        def __getattr__(self, name: str) -> Any: ...

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "/msg/" in cls._type:  # a service's request and response are no messages
            MESSAGE_TYPES[cls._type] = cls

    def __init__(self, **kwargs: Any) -> None:
        unknown = set(kwargs) - set(self._fields_and_field_types)
        if unknown:
            raise AssertionError(f"Invalid arguments passed to constructor: {sorted(unknown)}")
        for name, kind in self._fields_and_field_types.items():
            if name in kwargs:
                setattr(self, name, kwargs[name])
            elif name in self._field_defaults:
                setattr(self, name, self._field_defaults[name])
            else:
                object.__setattr__(self, name, _default(kind))

    def __setattr__(self, name: str, value: Any) -> None:
        kind = self._fields_and_field_types.get(name)
        if kind is None:
            raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")
        object.__setattr__(self, name, _convert(name, kind, value))

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        return dict(cls._fields_and_field_types)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return False
        return all(
            np.array_equal(getattr(self, f), getattr(other, f))
            if isinstance(getattr(self, f), np.ndarray)
            else getattr(self, f) == getattr(other, f)
            for f in self._fields_and_field_types
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        package, kind, name = self._type.split("/")  # kind: msg, or srv
        args = ", ".join(f"{f}={getattr(self, f)!r}" for f in self._fields_and_field_types)
        return f"{package}.{kind}.{name}({args})"


def declare(type_name: str, fields: dict[str, str], **extra: Any) -> type[Message]:
    """Declare one message class, e.g. ``declare("std_msgs/msg/String", {"data": "string"})``
    (or a service's request or response: ``std_srvs/srv/Trigger_Response``)."""
    name = type_name.split("/")[-1]
    namespace = {"_type": type_name, "_fields_and_field_types": fields, **extra}
    return type(name, (Message,), namespace)


def wire_copy(msg: Message) -> Message:
    """``msg`` as a subscriber receives it: a separate object whose float32 fields went
    through the middleware's float32 (0.12 arrives as 0.11999999731779099), as with
    real rclpy; every other value is copied exactly."""
    copy = type(msg).__new__(type(msg))
    for name, kind in msg._fields_and_field_types.items():
        object.__setattr__(copy, name, _wire_value(kind, getattr(msg, name)))
    return copy


def _wire_value(kind: str, value: Any) -> Any:
    if kind == "float":
        return struct.unpack("f", struct.pack("f", value))[0]
    if isinstance(value, Message):
        return wire_copy(value)
    if isinstance(value, list):
        return [wire_copy(item) if isinstance(item, Message) else item for item in value]
    if isinstance(value, (array.array, np.ndarray)):
        return value.copy() if isinstance(value, np.ndarray) else array.array(value.typecode, value)
    return value
