"""Conversions the handlers share: hostile-number filtering, angles, stamps, text.

Every function here accepts what any of the message flavours carries (rclpy, rosbags,
Cyclone DDS IDL samples, the mock): Python ints and floats, numpy scalars, ``bytes``
of length one. Anything that is not a finite number becomes None, so NaN and ±inf
never reach an event (JSON has neither, and orjson would silently write ``null``).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

from phytrace_edge.errors import MalformedMessage

TEXT_MAX_CHARS = 256


def finite(value: Any) -> float | None:
    """``value`` as a float when it is a finite real number, else None.

    Booleans are rejected: a bool in a numeric field is a wrong type, not a 0 or 1.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def integer(value: Any) -> int | None:
    """``value`` as an int for integral fields (uint8, int8, ...): int, numpy int,
    or a one-byte ``bytes`` as rclpy gives for the ROS ``byte`` type."""
    if isinstance(value, (bytes, bytearray)):
        return value[0] if len(value) == 1 else None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        return None
    return int(value)


def text(value: Any) -> str | None:
    """A string field, cut to the schema's 256 characters; None when not a string."""
    if isinstance(value, (bytes, bytearray)):
        value = bytes(value).decode("utf-8", "replace")
    if not isinstance(value, str):
        return None
    return value[:TEXT_MAX_CHARS]


def degrees(radians: Any) -> float | None:
    """Radians to degrees, None when not finite (before or after: 1e307 rad overflows)."""
    value = finite(radians)
    return None if value is None else finite(math.degrees(value))


def wrap_degrees(angle: float) -> float:
    """An angle in degrees folded into [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


def quaternion_to_rpy_deg(q: Any) -> tuple[float, float, float] | None:
    """Roll, pitch, yaw in degrees from a ``geometry_msgs/Quaternion``.

    The rotation is the REP-103 intrinsic z-y'-x'' sequence (yaw about z up, then
    pitch, then roll), the same as tf2's ``getRPY``. The quaternion is normalised
    first; a zero or non-finite one has no orientation and gives None.
    """
    parts = [finite(getattr(q, axis, None)) for axis in ("x", "y", "z", "w")]
    if any(part is None for part in parts):
        return None
    x, y, z, w = (float(part) for part in parts)  # type: ignore[arg-type]
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-9:
        return None
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sin_pitch = max(-1.0, min(1.0, 2.0 * (w * y - z * x)))
    pitch = math.asin(sin_pitch)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (
        wrap_degrees(math.degrees(roll)),
        math.degrees(pitch),
        wrap_degrees(math.degrees(yaw)),
    )


def compass_heading_deg(enu_yaw_deg: float) -> float:
    """Compass heading (0 = north, clockwise, [0, 360)) from a REP-103 ENU yaw
    (0 = east, counter-clockwise)."""
    heading = (90.0 - enu_yaw_deg) % 360.0
    return 0.0 if heading >= 360.0 else heading


def stamp_ns(header: Any) -> int | None:
    """A ``std_msgs/Header`` stamp in nanoseconds; None for a missing or zero stamp.

    A zero stamp means the publisher did not set it, not 1970.
    """
    stamp = getattr(header, "stamp", None)
    sec = integer(getattr(stamp, "sec", None))
    nanosec = integer(getattr(stamp, "nanosec", None))
    if sec is None or nanosec is None or (sec == 0 and nanosec == 0):
        return None
    return sec * 1_000_000_000 + nanosec


def xyz(vector: Any, keys: tuple[str, str, str] = ("x", "y", "z")) -> dict[str, float]:
    """A ``Vector3``/``Point`` as a dict of its finite components under ``keys``."""
    out = {}
    for axis, key in zip(("x", "y", "z"), keys, strict=True):
        value = finite(getattr(vector, axis, None))
        if value is not None:
            out[key] = value
    return out


def xyz_deg(vector: Any) -> dict[str, float]:
    """A ``Vector3`` in rad/s as a dict of finite components in degrees/s."""
    out = {}
    for axis in ("x", "y", "z"):
        value = degrees(getattr(vector, axis, None))
        if value is not None:
            out[axis] = value
    return out


def compact(value: Any) -> Any:
    """Drop None values and empty dicts, recursively: absent data means absent fields."""
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            item = compact(item)
            if item is not None and item != {}:
                out[key] = item
        return out
    if isinstance(value, list):
        return [compact(item) for item in value]
    return value


def header_fields(msg: Any) -> dict[str, Any]:
    """``stamp_ns`` and ``frame_id`` of a message's ``std_msgs/Header``."""
    header = getattr(msg, "header", None)
    return {"stamp_ns": stamp_ns(header), "frame_id": text(getattr(header, "frame_id", None))}


def pose_fields(pose: Any) -> dict[str, Any]:
    """``geometry_msgs/Pose`` -> position in metres and yaw in degrees."""
    position = xyz(getattr(pose, "position", None), ("x_m", "y_m", "z_m"))
    rpy = quaternion_to_rpy_deg(getattr(pose, "orientation", None))
    return {**position, "yaw_deg": rpy[2] if rpy else None}


def first_number(sequence: Any) -> float | None:
    """The first number of a sequence field, or None when there is none."""
    try:
        return finite(sequence[0])
    except (TypeError, IndexError, KeyError):
        return None


def sequence_items(msg: Any, name: str, limit: int) -> Any:
    """The first ``limit`` items of a sequence field: a list, ``array.array`` or numpy
    array (sliced, not copied item by item); an unset field is empty."""
    sequence = getattr(msg, name, None)
    if sequence is None:
        return ()
    if isinstance(sequence, (str, bytes)):
        raise MalformedMessage("bad_sequence", f"{name} is text, not a sequence")
    try:
        return sequence[:limit]
    except (TypeError, KeyError):
        raise MalformedMessage(
            "bad_sequence", f"{name} is {type(sequence).__name__}, not a sequence"
        ) from None
