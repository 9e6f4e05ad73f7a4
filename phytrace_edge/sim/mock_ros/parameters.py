"""Node parameters as real rclpy has them.

- A parameter must be declared before it is read (``ParameterNotDeclaredException``),
  and declared once (``ParameterAlreadyDeclaredException``); ``use_sim_time`` is
  declared by the node itself.
- Values given on the command line (``--ros-args -p name:=value``, ``--params-file``)
  are overrides: ``declare_parameter`` takes the override instead of its own value,
  unless told ``ignore_override=True``.
- A read-only parameter cannot be set: the result says why, nothing raises.
- ``rclpy.parameter``'s ``Parameter`` and ``parameter_value_to_python``, and the
  ``rcl_interfaces`` types the parameter services answer with.
"""

from __future__ import annotations

import enum
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any


class ParameterNotDeclaredException(Exception):
    pass


class ParameterAlreadyDeclaredException(Exception):
    pass


class ParameterType(enum.IntEnum):
    """``rcl_interfaces.msg.ParameterType`` (the scalar kinds the bridge uses)."""

    PARAMETER_NOT_SET = 0
    PARAMETER_BOOL = 1
    PARAMETER_INTEGER = 2
    PARAMETER_DOUBLE = 3
    PARAMETER_STRING = 4


def type_of(value: Any) -> ParameterType:
    if value is None:
        return ParameterType.PARAMETER_NOT_SET
    if isinstance(value, bool):
        return ParameterType.PARAMETER_BOOL
    if isinstance(value, int):
        return ParameterType.PARAMETER_INTEGER
    if isinstance(value, float):
        return ParameterType.PARAMETER_DOUBLE
    if isinstance(value, str):
        return ParameterType.PARAMETER_STRING
    raise TypeError(f"the mock has no parameter type for {type(value).__name__}")


@dataclass(frozen=True)
class ParameterDescriptor:
    """``rcl_interfaces.msg.ParameterDescriptor``: the fields the bridge sets."""

    name: str = ""
    type: int = 0
    description: str = ""
    read_only: bool = False
    dynamic_typing: bool = False


@dataclass(frozen=True)
class ParameterValue:
    """``rcl_interfaces.msg.ParameterValue`` (scalars)."""

    type: int = ParameterType.PARAMETER_NOT_SET
    bool_value: bool = False
    integer_value: int = 0
    double_value: float = 0.0
    string_value: str = ""


@dataclass(frozen=True)
class SetParametersResult:
    successful: bool
    reason: str = ""


class Parameter:
    """``rclpy.parameter.Parameter``: a name and a value."""

    Type = ParameterType

    def __init__(self, name: str, type_: ParameterType | None = None, value: Any = None) -> None:
        self.name, self.value = name, value
        self.type_ = type_ if type_ is not None else type_of(value)

    def get_parameter_value(self) -> ParameterValue:
        fields = {
            ParameterType.PARAMETER_BOOL: "bool_value",
            ParameterType.PARAMETER_INTEGER: "integer_value",
            ParameterType.PARAMETER_DOUBLE: "double_value",
            ParameterType.PARAMETER_STRING: "string_value",
        }
        name = fields.get(self.type_)
        return ParameterValue(self.type_, **({name: self.value} if name else {}))


def parameter_value_to_python(value: ParameterValue) -> Any:
    """``rclpy.parameter.parameter_value_to_python``: None for a parameter not set."""
    return {
        ParameterType.PARAMETER_NOT_SET: None,
        ParameterType.PARAMETER_BOOL: value.bool_value,
        ParameterType.PARAMETER_INTEGER: value.integer_value,
        ParameterType.PARAMETER_DOUBLE: value.double_value,
        ParameterType.PARAMETER_STRING: value.string_value,
    }[ParameterType(value.type)]


class Parameters:
    """The parameter API of ``rclpy.node.Node``, with the overrides this node gets."""

    def __init__(self, overrides: dict[str, Any] | None = None) -> None:
        self.overrides = overrides or {}
        self._values: dict[str, Parameter] = {}
        self._descriptors: dict[str, ParameterDescriptor] = {}
        self.declare_parameter("use_sim_time", False)

    def declare_parameter(
        self,
        name: str,
        value: Any = None,
        descriptor: ParameterDescriptor | None = None,
        ignore_override: bool = False,
    ) -> Parameter:
        if name in self._values:
            raise ParameterAlreadyDeclaredException(name)
        if name in self.overrides and not ignore_override:
            value = self.overrides[name]
        parameter = Parameter(name, value=value)
        descriptor = descriptor or ParameterDescriptor()
        self._values[name] = parameter
        self._descriptors[name] = ParameterDescriptor(
            name, parameter.type_, descriptor.description, descriptor.read_only,
            descriptor.dynamic_typing,
        )  # fmt: skip
        return parameter

    def has_parameter(self, name: str) -> bool:
        return name in self._values

    def get_parameter(self, name: str) -> Parameter:
        if name not in self._values:
            raise ParameterNotDeclaredException(name)
        return self._values[name]

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def set_parameter(self, parameter: Parameter) -> SetParametersResult:
        descriptor = self._descriptors.get(parameter.name)
        if descriptor is None:
            return SetParametersResult(False, "parameter not declared")
        if descriptor.read_only:
            return SetParametersResult(
                False, f"Trying to set a read-only parameter: {parameter.name}"
            )
        self._values[parameter.name] = parameter
        return SetParametersResult(True)

    def parameter_names(self) -> Iterator[str]:
        return iter(sorted(self._values))


def overrides_from_arguments(args: list[str], node_fqn: str) -> dict[str, Any]:
    """rcl's parameter overrides for one node from the arguments after ``--ros-args``:
    ``-p name:=value`` (a YAML value) and ``--params-file`` sections for ``/**`` or for
    the node, applied in the order given (a later one wins)."""
    ros_args = args[args.index("--ros-args") + 1 :] if "--ros-args" in args else []
    overrides: dict[str, Any] = {}
    for flag, value in itertools.pairwise(ros_args):
        if flag in ("-p", "--param") and ":=" in value:
            import yaml  # rcl reads parameter values as YAML

            name, _, text = value.partition(":=")
            overrides[name] = yaml.safe_load(text)
        elif flag == "--params-file":
            overrides.update(_params_file_overrides(value, node_fqn))
    return overrides


def _params_file_overrides(path: str, node_fqn: str) -> dict[str, Any]:
    import yaml

    document = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    name = node_fqn.rsplit("/", 1)[-1]
    keys = {"/**", node_fqn, node_fqn.lstrip("/"), f"/**/{name}"}
    overrides: dict[str, Any] = {}
    for key, section in document.items():
        if key in keys:
            overrides.update(section.get("ros__parameters", {}))
    return overrides
