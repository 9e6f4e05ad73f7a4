"""Cyclone DDS types made at run time from ROS message definitions, for the topics of
``TOPICS_EXTRA`` on the ``dds`` input.

The definitions are the rosbags type store's (ROS 2 Jazzy's standard messages); each
becomes an ``IdlStruct`` named as ROS 2 names it on the wire
(``pkg::msg::dds_::Type_``), with the field types of the ROS IDL, as ``dds_types.py``
declares the table's by hand. A type the store does not know cannot be read: the
caller skips the topic and says why.
"""

from __future__ import annotations

import functools
import types
from dataclasses import dataclass
from typing import Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as idl_types

# the IDL markers are indexed at run time (sequence[T], array[T, N]), which their
# stubs do not declare
idl: Any = idl_types

_BASE = {
    "bool": bool,
    "byte": idl.byte,
    "char": idl.char,
    "int8": idl.int8,
    "uint8": idl.uint8,
    "int16": idl.int16,
    "uint16": idl.uint16,
    "int32": idl.int32,
    "uint32": idl.uint32,
    "int64": idl.int64,
    "uint64": idl.uint64,
    "float32": idl.float32,
    "float64": idl.float64,
}


@functools.cache
def _jazzy() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def fielddefs() -> Any:
    """The message definitions the DDS input knows (the rosbags Jazzy store's)."""
    return _jazzy().fielddefs


@functools.cache
def idl_type(type_name: str) -> type[IdlStruct]:
    """The IdlStruct of ROS type ``type_name``; KeyError when it is not known."""
    _, fields = fielddefs()[type_name]
    package, _, name = type_name.partition("/msg/")
    annotations = {field: _annotation(node) for field, node in fields}

    def body(namespace: dict[str, Any]) -> None:
        namespace["__annotations__"] = annotations
        namespace["__msgtype__"] = type_name  # what ingest.generic reads the type from

    cls = types.new_class(
        f"{name}_", (IdlStruct,), {"typename": f"{package}::msg::dds_::{name}_"}, body
    )
    return dataclass(cls)


def _annotation(node: tuple[Any, Any]) -> Any:
    nodetype, description = int(node[0]), node[1]
    if nodetype == 1:  # BASE: (name, string bound)
        base, bound = description
        if base == "string":
            return idl.bounded_str[bound] if bound else str
        return _BASE[base]
    if nodetype == 2:  # NAME: another message
        return idl_type(description)
    item, count = description
    if nodetype == 3:  # ARRAY of a fixed size
        return idl.array[_annotation(item), count]
    return idl.sequence[_annotation(item), count] if count else idl.sequence[_annotation(item)]
