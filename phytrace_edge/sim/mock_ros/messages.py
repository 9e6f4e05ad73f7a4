"""Message classes of the ten bridged topics, with the field types real rclpy gives.

Each class declares ``_fields_and_field_types`` exactly as rosidl_generator_py does,
and the setters convert and check values the way the generated code does:

- ``float`` (float32) / ``double`` -> Python float; ints of any width -> int
- ``octet`` (the ROS ``byte`` type) -> ``bytes`` of length 1, e.g. ``b'\\x02'``
- ``sequence<float>`` / ``sequence<double>`` -> ``array.array('f')`` / ``array.array('d')``
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
_ARRAY_TYPECODES = {"float": "f", "double": "d"}
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
            return array.array(code, [_check_float(name, item, v) for v in value])
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
        package, _, name = self._type.split("/")
        args = ", ".join(f"{f}={getattr(self, f)!r}" for f in self._fields_and_field_types)
        return f"{package}.msg.{name}({args})"


def _message(type_name: str, fields: dict[str, str], **extra: Any) -> type[Message]:
    """Declare one message class, e.g. ``_message("std_msgs/msg/String", {"data": "string"})``."""
    name = type_name.split("/")[-1]
    namespace = {"_type": type_name, "_fields_and_field_types": fields, **extra}
    return type(name, (Message,), namespace)


Time = _message("builtin_interfaces/msg/Time", {"sec": "int32", "nanosec": "uint32"})
Header = _message("std_msgs/msg/Header", {"stamp": "builtin_interfaces/Time", "frame_id": "string"})
String = _message("std_msgs/msg/String", {"data": "string"})
Point = _message("geometry_msgs/msg/Point", {"x": "double", "y": "double", "z": "double"})
Vector3 = _message("geometry_msgs/msg/Vector3", {"x": "double", "y": "double", "z": "double"})
Quaternion = _message(
    "geometry_msgs/msg/Quaternion",
    {"x": "double", "y": "double", "z": "double", "w": "double"},
    _field_defaults={"w": 1.0},
)
Pose = _message(
    "geometry_msgs/msg/Pose",
    {"position": "geometry_msgs/Point", "orientation": "geometry_msgs/Quaternion"},
)
PoseWithCovariance = _message(
    "geometry_msgs/msg/PoseWithCovariance",
    {"pose": "geometry_msgs/Pose", "covariance": "double[36]"},
)
Twist = _message(
    "geometry_msgs/msg/Twist",
    {"linear": "geometry_msgs/Vector3", "angular": "geometry_msgs/Vector3"},
)
TwistWithCovariance = _message(
    "geometry_msgs/msg/TwistWithCovariance",
    {"twist": "geometry_msgs/Twist", "covariance": "double[36]"},
)
PoseStamped = _message(
    "geometry_msgs/msg/PoseStamped", {"header": "std_msgs/Header", "pose": "geometry_msgs/Pose"}
)
TwistStamped = _message(
    "geometry_msgs/msg/TwistStamped",
    {"header": "std_msgs/Header", "twist": "geometry_msgs/Twist"},
)
Odometry = _message(
    "nav_msgs/msg/Odometry",
    {
        "header": "std_msgs/Header",
        "child_frame_id": "string",
        "pose": "geometry_msgs/PoseWithCovariance",
        "twist": "geometry_msgs/TwistWithCovariance",
    },
)
BatteryState = _message(
    "sensor_msgs/msg/BatteryState",
    {
        "header": "std_msgs/Header",
        "voltage": "float",
        "temperature": "float",
        "current": "float",
        "charge": "float",
        "capacity": "float",
        "design_capacity": "float",
        "percentage": "float",
        "power_supply_status": "uint8",
        "power_supply_health": "uint8",
        "power_supply_technology": "uint8",
        "present": "boolean",
        "cell_voltage": "sequence<float>",
        "cell_temperature": "sequence<float>",
        "location": "string",
        "serial_number": "string",
    },
    POWER_SUPPLY_STATUS_UNKNOWN=0,
    POWER_SUPPLY_STATUS_CHARGING=1,
    POWER_SUPPLY_STATUS_DISCHARGING=2,
    POWER_SUPPLY_STATUS_NOT_CHARGING=3,
    POWER_SUPPLY_STATUS_FULL=4,
    POWER_SUPPLY_HEALTH_UNKNOWN=0,
    POWER_SUPPLY_HEALTH_GOOD=1,
    POWER_SUPPLY_HEALTH_OVERHEAT=2,
    POWER_SUPPLY_TECHNOLOGY_LION=2,
)
LaserScan = _message(
    "sensor_msgs/msg/LaserScan",
    {
        "header": "std_msgs/Header",
        "angle_min": "float",
        "angle_max": "float",
        "angle_increment": "float",
        "time_increment": "float",
        "scan_time": "float",
        "range_min": "float",
        "range_max": "float",
        "ranges": "sequence<float>",
        "intensities": "sequence<float>",
    },
)
Imu = _message(
    "sensor_msgs/msg/Imu",
    {
        "header": "std_msgs/Header",
        "orientation": "geometry_msgs/Quaternion",
        "orientation_covariance": "double[9]",
        "angular_velocity": "geometry_msgs/Vector3",
        "angular_velocity_covariance": "double[9]",
        "linear_acceleration": "geometry_msgs/Vector3",
        "linear_acceleration_covariance": "double[9]",
    },
)
NavSatStatus = _message(
    "sensor_msgs/msg/NavSatStatus",
    {"status": "int8", "service": "uint16"},
    STATUS_UNKNOWN=-2,
    STATUS_NO_FIX=-1,
    STATUS_FIX=0,
    STATUS_SBAS_FIX=1,
    STATUS_GBAS_FIX=2,
    SERVICE_GPS=1,
    SERVICE_GLONASS=2,
    SERVICE_COMPASS=4,
    SERVICE_GALILEO=8,
)
NavSatFix = _message(
    "sensor_msgs/msg/NavSatFix",
    {
        "header": "std_msgs/Header",
        "status": "sensor_msgs/NavSatStatus",
        "latitude": "double",
        "longitude": "double",
        "altitude": "double",
        "position_covariance": "double[9]",
        "position_covariance_type": "uint8",
    },
    COVARIANCE_TYPE_UNKNOWN=0,
    COVARIANCE_TYPE_APPROXIMATED=1,
    COVARIANCE_TYPE_DIAGONAL_KNOWN=2,
    COVARIANCE_TYPE_KNOWN=3,
)
JointState = _message(
    "sensor_msgs/msg/JointState",
    {
        "header": "std_msgs/Header",
        "name": "sequence<string>",
        "position": "sequence<double>",
        "velocity": "sequence<double>",
        "effort": "sequence<double>",
    },
)
KeyValue = _message("diagnostic_msgs/msg/KeyValue", {"key": "string", "value": "string"})
DiagnosticStatus = _message(
    "diagnostic_msgs/msg/DiagnosticStatus",
    {
        "level": "octet",
        "name": "string",
        "message": "string",
        "hardware_id": "string",
        "values": "sequence<diagnostic_msgs/KeyValue>",
    },
    OK=b"\x00",
    WARN=b"\x01",
    ERROR=b"\x02",
    STALE=b"\x03",
)
DiagnosticArray = _message(
    "diagnostic_msgs/msg/DiagnosticArray",
    {"header": "std_msgs/Header", "status": "sequence<diagnostic_msgs/DiagnosticStatus>"},
)


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


def message_type(type_name: str) -> type[Message]:
    """The mock class for a ROS type name such as ``sensor_msgs/msg/Imu``."""
    return MESSAGE_TYPES[type_name]
