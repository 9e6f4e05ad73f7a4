"""Any ROS message -> JSON-ready data, for the topics of ``TOPICS_EXTRA``.

Pure, and the same for every flavour of message (rclpy, the mock, rosbags, Cyclone
DDS samples). What a value means is taken from the field's ROS type, given as rosidl
spells it (``float``, ``double``, ``sequence<uint8>``, ``uint8[16]``,
``geometry_msgs/Vector3``): rclpy's ``get_fields_and_field_types`` gives those, and
``rosbags_field_types`` turns a rosbags type store's definitions into them.

The rules (docs/udm.md, "telemetry.topic"):

- float32 values are the shortest decimal that reads back as the same float32, as in
  the handlers; float64 values are written as they are.
- NaN and ±inf: a scalar field is left out (as the handlers do); an array element
  becomes null (its position matters).
- ``uint8[]`` and ``byte[]`` (images, blobs) become base64 text, as rosbridge does.
- An array (or a blob) longer than ``max_array`` becomes ``{"len": n, "head": [...]}``
  (a blob's head is base64 of its first ``max_array`` bytes).
- Text is cut to ``TEXT_MAX_CHARS``, and what UTF-8 cannot carry (a lone surrogate)
  becomes U+FFFD (``safe_text.py``); ``message_data`` counts the strings repaired in
  the ``Repairs`` it is given.
"""

from __future__ import annotations

import base64
import math
import numbers
import re
from collections.abc import Callable, Mapping
from typing import Any

from phytrace_edge.ingest.convert import f32
from phytrace_edge.ingest.safe_text import safe_str

TEXT_MAX_CHARS = 2048
FieldTypes = Callable[[Any], Mapping[str, str]]  # message -> {field: rosidl type}

_BLOB_ITEMS = {"uint8", "octet", "byte"}
_ARRAY = re.compile(r"^(?:sequence<([^,>]+)(?:, ?\d+)?>|([^\[]+)\[(?:<=)?\d*\])$")
_MISSING = object()


def rosidl_field_types(msg: Any) -> Mapping[str, str]:
    """The field types of an rclpy (or mock) message, as its class declares them."""
    types: Mapping[str, str] = type(msg).get_fields_and_field_types()
    return types


def message_type_name(msg: Any) -> str:
    """The ROS type of a message object, e.g. ``sensor_msgs/msg/Temperature``: rosbags
    and the DDS types say it (``__msgtype__``), the mock too (``_type``); rclpy's
    generated classes live in ``<package>.msg._<module>``."""
    named = getattr(msg, "__msgtype__", None) or getattr(msg, "_type", None)
    if isinstance(named, str):
        return named
    cls = type(msg)
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


class Repairs:
    """How many strings of the messages converted with it had to be repaired."""

    __slots__ = ("count",)

    def __init__(self) -> None:
        self.count = 0

    def text(self, value: str) -> str:
        """``value`` cut to ``TEXT_MAX_CHARS`` and safe for JSON; a repair counted."""
        text, repaired = safe_str(str(value[:TEXT_MAX_CHARS]))
        self.count += repaired
        return text


def message_data(
    msg: Any, field_types: FieldTypes, max_array: int, repairs: Repairs | None = None
) -> dict[str, Any]:
    """``msg`` as a JSON-ready dict (see the module doc); never raises for odd values.
    Strings repaired on the way are counted in ``repairs``."""
    tally = Repairs() if repairs is None else repairs
    data: dict[str, Any] = {}
    for name, kind in field_types(msg).items():
        value = _value(getattr(msg, name, _MISSING), kind, field_types, max_array, tally)
        if value is not _MISSING:
            data[name] = value
    return data


def _value(value: Any, kind: str, field_types: FieldTypes, max_array: int, repairs: Repairs) -> Any:
    """One field; ``_MISSING`` when it is left out (absent, NaN or inf)."""
    if value is _MISSING:
        return _MISSING
    array = _ARRAY.match(kind)
    if array:
        item_kind = array.group(1) or array.group(2)
        if item_kind in _BLOB_ITEMS:
            return _blob(value, max_array)
        items = [
            _item(v, item_kind, field_types, max_array, repairs) for v in _head(value, max_array)
        ]
        return _bounded(items, len(value), max_array)
    if _is_message(value):
        return message_data(value, field_types, max_array, repairs)
    if isinstance(value, str):
        return repairs.text(value)
    return _scalar(value, kind)


def _item(value: Any, kind: str, field_types: FieldTypes, max_array: int, repairs: Repairs) -> Any:
    """An array element: a number that is not finite is null, not left out."""
    converted = _value(value, kind, field_types, max_array, repairs)
    return None if converted is _MISSING else converted


def _scalar(value: Any, kind: str) -> Any:
    if isinstance(value, bool) or type(value).__name__ == "bool_":  # numpy's bool
        return bool(value)
    if isinstance(value, (bytes, bytearray)):  # rclpy's ``byte``: one byte as bytes
        return value[0] if len(value) == 1 else base64.b64encode(value).decode("ascii")
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        if kind == "float":
            number = f32(value)
            return _MISSING if number is None else number
        number = float(value)
        return number if math.isfinite(number) else _MISSING
    return _MISSING  # text is read by ``_value``: its repairs are counted there


def _is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types") or hasattr(value, "__dataclass_fields__")


def _head(value: Any, max_array: int) -> Any:
    if hasattr(value, "tolist"):  # a numpy or ``array.array`` sequence
        return value[:max_array].tolist()
    return value[:max_array] if len(value) > max_array else value


def _bounded(items: list[Any], length: int, max_array: int) -> Any:
    return items if length <= max_array else {"len": length, "head": items}


def _blob(value: Any, max_array: int) -> Any:
    """uint8[] / byte[] as base64: ``bytes``, numpy or ``array('B')``, or rclpy's list
    of one-byte ``bytes``."""
    if isinstance(value, (list, tuple)):
        raw = b"".join(v if isinstance(v, bytes) else bytes((int(v) & 0xFF,)) for v in value)
    elif hasattr(value, "astype"):  # numpy, read without importing it
        raw = value.astype("uint8").tobytes()
    else:
        raw = bytes(value)
    text = base64.b64encode(raw[:max_array]).decode("ascii")
    return text if len(raw) <= max_array else {"len": len(raw), "head": text}


def rosbags_field_types(fielddefs: Mapping[str, Any]) -> FieldTypes:
    """Field types of rosbags messages (``msg.__msgtype__``) from a type store's
    ``fielddefs``, in rosidl's spelling."""
    cache: dict[str, dict[str, str]] = {}

    def field_types(msg: Any) -> Mapping[str, str]:
        msgtype = msg.__msgtype__
        if msgtype not in cache:
            cache[msgtype] = {name: _rosidl(node) for name, node in fielddefs[msgtype][1]}
        return cache[msgtype]

    return field_types


_ROSIDL_BASE = {"float32": "float", "float64": "double", "bool": "boolean", "byte": "octet"}


def _rosidl(node: tuple[Any, Any]) -> str:
    """A rosbags field node (nodetype, description) as a rosidl type string."""
    nodetype, description = int(node[0]), node[1]
    if nodetype == 1:  # BASE: (name, string bound)
        return str(_ROSIDL_BASE.get(description[0], description[0]))
    if nodetype == 2:  # NAME: pkg/msg/Type
        package, _, name = description.rpartition("/msg/")
        return f"{package}/{name}"
    item, count = description
    if nodetype == 3:  # ARRAY of a fixed size
        return f"{_rosidl(item)}[{count}]"
    return f"sequence<{_rosidl(item)}>"  # SEQUENCE
