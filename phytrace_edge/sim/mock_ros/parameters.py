"""Node parameters as real rclpy has them: a parameter must be declared before it is
read (``ParameterNotDeclaredException``), declared once
(``ParameterAlreadyDeclaredException``), and ``use_sim_time`` is declared by the node
itself. Command-line overrides are not modelled."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


class ParameterNotDeclaredException(Exception):
    pass


class ParameterAlreadyDeclaredException(Exception):
    pass


@dataclass(frozen=True)
class ParameterDescriptor:
    """``rcl_interfaces.msg.ParameterDescriptor``: the fields the bridge sets."""

    description: str = ""
    read_only: bool = False
    dynamic_typing: bool = False


@dataclass(frozen=True)
class Parameter:
    name: str
    value: Any
    descriptor: ParameterDescriptor


class Parameters:
    """The parameter API of ``rclpy.node.Node``."""

    def __init__(self) -> None:
        self._parameters: dict[str, Parameter] = {}
        self.declare_parameter("use_sim_time", False)

    def declare_parameter(
        self, name: str, value: Any = None, descriptor: ParameterDescriptor | None = None
    ) -> Parameter:
        if name in self._parameters:
            raise ParameterAlreadyDeclaredException(name)
        parameter = Parameter(name, value, descriptor or ParameterDescriptor())
        self._parameters[name] = parameter
        return parameter

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        return self._parameters[name]
