"""Conversions the handlers share: hostile-number filtering, precision, angles, stamps,
text (cut to the schema's length and made safe for JSON: ``safe_text.py``).

Every function here accepts what any of the message flavours carries (rclpy, rosbags,
Cyclone DDS IDL samples, the mock): Python ints and floats, numpy scalars and arrays
(read through the ``numbers`` ABCs and ``tolist``, so numpy is never imported here),
``bytes`` of length one. Anything that is not a finite number becomes None, so NaN and ±inf
never reach an event (JSON has neither, and orjson would silently write ``null``).

Values keep their real precision and no more (docs/udm.md has the table): a float32
field is written as the shortest decimal that reads back as the same float32
(``range_min`` 0.12f is ``0.12``, not ``0.11999999731779099``), and a value the bridge
derives (degrees from radians, a percentage, a speed) is rounded to a resolution per
field. Handlers run for every message of every topic, so the common cases (a plain
float or int) take the shortest path.
"""

from __future__ import annotations

import math
import numbers
import struct
from collections.abc import Sequence
from typing import Any

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.safe_text import TEXT_REPAIRED, safe_bytes, safe_str

TEXT_MAX_CHARS = 256
# Resolutions of derived values, as steps per unit (docs/udm.md).
MM = 1e3  # metres: 1 mm; m/s, m/s²: 1 mm/s, 1 mm/s²
MILLIDEGREE = 1e3  # degrees and degrees per second: 0.001°
PERCENT = 1e2  # 0.01 %
LATLON = 1e7  # 1e-7° (about 1 cm)
RAD = 1e5  # radians (joint positions): 1e-5 rad
RAD_S = 1e4  # rad/s: 1e-4 rad/s

_FLOAT32 = struct.Struct("<f")
F32_MAX = 3.4028234663852886e38
_PLAIN_NUMBERS = {float, int}
_DEGREES_PER_RADIAN = 180.0 / math.pi


def finite(value: Any) -> float | None:
    """``value`` as a float when it is a finite real number, else None.

    Booleans are rejected: a bool in a numeric field is a wrong type, not a 0 or 1.
    """
    kind = type(value)
    if kind is float:
        return value if math.isfinite(value) else None
    if kind is int:
        return float(value) if -1e308 < value < 1e308 else None
    if kind is bool or not isinstance(value, numbers.Real):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def rounded(value: Any, steps: float) -> float | None:
    """A finite number rounded to 1/``steps`` (``MM`` = 1000: to the millimetre), else
    None. ``round(x * steps) / steps`` is the double nearest the rounded decimal, so it
    prints as that decimal, and costs a quarter of ``round(x, 3)``."""
    number: float | None = value if type(value) is float else finite(value)
    if number is None:
        return None
    scaled = number * steps
    if scaled - scaled != 0.0:  # NaN or inf, or a finite value too large to scale
        return number if math.isfinite(number) else None
    return round(scaled) / steps


def snap(number: float, steps: float) -> float:
    """A finite ``number`` rounded to 1/``steps``."""
    scaled = number * steps
    return round(scaled) / steps if math.isfinite(scaled) else number


def single(number: float) -> float:
    """A finite double within float32's range, rounded to the nearest float32."""
    return float(_FLOAT32.unpack(_FLOAT32.pack(number))[0])


def shortest_f32(value: float) -> float:
    """The shortest decimal that reads back as the float32 ``value`` (what numpy
    prints for a float32). A decimal of d digits that reads back implies one of d + 1
    does, so the digits are found by bisection over 1..9 (9 always read back)."""
    low, high = 1, 9
    while low < high:
        middle = (low + high) // 2
        candidate = float(f"{value:.{middle}g}")
        try:
            reads_back = single(candidate) == value
        except OverflowError:  # rounded past float32's largest value
            reads_back = False
        if reads_back:
            high = middle
        else:
            low = middle + 1
    return float(f"{value:.{low}g}")


def f32(value: Any) -> float | None:
    """A float32 field at its real precision: the shortest decimal that reads back as
    the same float32, else None."""
    number = finite(value)
    if number is None or not -F32_MAX <= number <= F32_MAX:
        return None
    return shortest_f32(single(number))


def f32_all(values: Sequence[Any], items: Any = ()) -> list[float | None]:
    """``f32`` of many values (a battery's fields), then of the numbers in ``items``
    (its cells; what float32 cannot hold is None); an item that is not a number raises
    TypeError."""
    converted = [f32(value) for value in values]
    for item in float_array(items):
        converted.append(f32(item))
    return converted


def integer(value: Any) -> int | None:
    """``value`` as an int for integral fields (uint8, int8, ...): int, numpy int,
    or a one-byte ``bytes`` as rclpy gives for the ROS ``byte`` type."""
    kind = type(value)
    if kind is int:
        return int(value)
    if kind is bytes or kind is bytearray:
        return value[0] if len(value) == 1 else None
    if kind is bool or not isinstance(value, numbers.Integral):
        return None
    return int(value)


def text(value: Any) -> str | None:
    """A string field, cut to the schema's 256 characters and safe for JSON; None when
    not a string."""
    return checked_text(value)[0]


def checked_text(value: Any, limit: int = TEXT_MAX_CHARS) -> tuple[str | None, bool]:
    """A string field cut to ``limit`` characters, with what UTF-8 cannot carry
    replaced by U+FFFD (``safe_text``), and whether anything was; None when not a
    string. ``bytes`` are read as UTF-8."""
    if type(value) is str:
        cut = value[:limit]
        return (cut, False) if cut.isascii() else safe_str(cut)
    if isinstance(value, (bytes, bytearray)):
        decoded, repaired = safe_bytes(value)
        return decoded[:limit], repaired
    if not isinstance(value, str):
        return None, False
    return safe_str(str(value[:limit]))


def degrees(radians: Any) -> float | None:
    """Radians to degrees, to 0.001°; None when not finite (before or after: 1e307 rad
    overflows)."""
    if type(radians) is not float:
        radians = finite(radians)
        if radians is None:
            return None
    converted = radians * _DEGREES_PER_RADIAN
    return rounded(converted, MILLIDEGREE) if math.isfinite(converted) else None


def wrap_degrees(angle: float) -> float:
    """An angle in degrees folded into [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


def quaternion_to_rpy_deg(q: Any) -> tuple[float, float, float] | None:
    """Roll, pitch, yaw in degrees (to 0.001°) from a ``geometry_msgs/Quaternion``.

    The rotation is the REP-103 intrinsic z-y'-x'' sequence (yaw about z up, then
    pitch, then roll), the same as tf2's ``getRPY``. The quaternion is normalised
    first; a zero or non-finite one has no orientation and gives None.
    """
    x, y = finite(getattr(q, "x", None)), finite(getattr(q, "y", None))
    z, w = finite(getattr(q, "z", None)), finite(getattr(q, "w", None))
    if x is None or y is None or z is None or w is None:
        return None
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-9:
        return None
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sin_pitch = max(-1.0, min(1.0, 2.0 * (w * y - z * x)))
    pitch = math.asin(sin_pitch)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    # atan2 and asin are finite here: no need for snap's check
    return (
        round(((roll * _DEGREES_PER_RADIAN + 180.0) % 360.0 - 180.0) * MILLIDEGREE) / MILLIDEGREE,
        round(pitch * _DEGREES_PER_RADIAN * MILLIDEGREE) / MILLIDEGREE,
        round(((yaw * _DEGREES_PER_RADIAN + 180.0) % 360.0 - 180.0) * MILLIDEGREE) / MILLIDEGREE,
    )


def quaternion_to_yaw_deg(q: Any) -> float | None:
    """The yaw alone (a pose's heading in its frame), as in ``quaternion_to_rpy_deg``."""
    x, y = finite(getattr(q, "x", None)), finite(getattr(q, "y", None))
    z, w = finite(getattr(q, "z", None)), finite(getattr(q, "w", None))
    if x is None or y is None or z is None or w is None:
        return None
    norm2 = x * x + y * y + z * z + w * w
    if not math.isfinite(norm2) or norm2 < 1e-18:
        return None
    yaw = math.atan2(2.0 * (w * z + x * y) / norm2, 1.0 - 2.0 * (y * y + z * z) / norm2)
    return snap(wrap_degrees(math.degrees(yaw)), MILLIDEGREE)


def compass_heading_deg(enu_yaw_deg: float) -> float:
    """Compass heading (0 = north, clockwise, [0, 360)) from a REP-103 ENU yaw
    (0 = east, counter-clockwise)."""
    heading = snap((90.0 - enu_yaw_deg) % 360.0, MILLIDEGREE)
    return 0.0 if heading >= 360.0 else heading


def stamp_ns(header: Any) -> int | None:
    """A ``std_msgs/Header`` stamp in nanoseconds; None for a missing or zero stamp.

    A zero stamp means the publisher did not set it, not 1970.
    """
    stamp = getattr(header, "stamp", None)
    sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if type(sec) is not int or type(nanosec) is not int:
        sec, nanosec = integer(sec), integer(nanosec)
        if sec is None or nanosec is None:
            return None
    if sec == 0 and nanosec == 0:
        return None
    return sec * 1_000_000_000 + nanosec


def xyz(
    vector: Any, keys: tuple[str, str, str] = ("x", "y", "z"), steps: float = MM
) -> dict[str, float]:
    """A ``Vector3``/``Point`` as a dict of its finite components under ``keys``."""
    x = rounded(getattr(vector, "x", None), steps)
    y = rounded(getattr(vector, "y", None), steps)
    z = rounded(getattr(vector, "z", None), steps)
    if x is not None and y is not None and z is not None:
        return {keys[0]: x, keys[1]: y, keys[2]: z}
    return {key: v for key, v in zip(keys, (x, y, z), strict=True) if v is not None}


def xyz_deg(vector: Any, keys: tuple[str, str, str] = ("x", "y", "z")) -> dict[str, float]:
    """A ``Vector3`` in rad/s as a dict of finite components in degrees/s."""
    x = degrees(getattr(vector, "x", None))
    y = degrees(getattr(vector, "y", None))
    z = degrees(getattr(vector, "z", None))
    if x is not None and y is not None and z is not None:
        return {keys[0]: x, keys[1]: y, keys[2]: z}
    return {key: v for key, v in zip(keys, (x, y, z), strict=True) if v is not None}


def present(**values: Any) -> dict[str, Any]:
    """The given fields without the absent ones (None or an empty dict): absent data
    means absent fields, never nulls."""
    return {key: value for key, value in values.items() if value is not None and value != {}}


def header_fields(msg: Any) -> dict[str, Any]:
    """``stamp_ns`` and ``frame_id`` of a message's ``std_msgs/Header``, and
    ``text_repaired`` when the frame id had to be made safe (``checked_text``)."""
    header = getattr(msg, "header", None)
    fields: dict[str, Any] = {}
    stamp = stamp_ns(header)
    if stamp is not None:
        fields["stamp_ns"] = stamp
    raw = getattr(header, "frame_id", None)
    if type(raw) is str and raw.isascii():  # the common case, on every message
        frame: str | None = raw[:TEXT_MAX_CHARS]
    else:
        frame, repaired = checked_text(raw)
        if repaired:
            fields[TEXT_REPAIRED] = 1
    if frame is not None:
        fields["frame_id"] = frame
    return fields


def add_repairs(reading: dict[str, Any], count: int) -> None:
    """Add ``count`` repaired strings to a reading's ``text_repaired`` (the dispatcher
    counts the message once under that reason)."""
    if count:
        reading[TEXT_REPAIRED] = reading.get(TEXT_REPAIRED, 0) + count


def pose_fields(pose: Any) -> dict[str, Any]:
    """``geometry_msgs/Pose`` -> position in metres and yaw in degrees."""
    position = xyz(getattr(pose, "position", None), ("x_m", "y_m", "z_m"))
    yaw = quaternion_to_yaw_deg(getattr(pose, "orientation", None))
    if yaw is not None:
        position["yaw_deg"] = yaw
    return position


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


def float_array(sequence: Any) -> list[float]:
    """A numeric sequence as a flat list of numbers (NaN and inf kept): rclpy gives
    ``array.array``, rosbags and DDS numpy arrays (flattened by their own ``ravel``),
    others lists. An item that is not a number raises TypeError. Runs once per scan
    on 1000+ ranges, so the common cases are checked by type, in C, not item by item."""
    if hasattr(sequence, "ravel"):
        sequence = sequence.ravel()
    if hasattr(sequence, "tolist"):  # numpy or array.array: numbers, unless text
        kind = getattr(getattr(sequence, "dtype", None), "kind", None) or sequence.typecode
        if kind not in ("f", "i", "u", "b", "d", "B", "h", "H", "I", "l", "L", "q", "Q"):
            raise TypeError(f"an array of {kind!r} is not numeric")
        items: list[Any] = sequence.tolist()
        return items
    items = list(sequence)
    if set(map(type, items)) <= _PLAIN_NUMBERS:
        return items
    if not all(map(_is_real, items)):
        raise TypeError("an item is not a number")
    return [float(item) for item in items]


def _is_real(value: Any) -> bool:
    kind = type(value)
    return kind is float or kind is int or (kind is not bool and isinstance(value, numbers.Real))
