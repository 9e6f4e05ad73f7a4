"""The mock laid out as rclpy's modules, for code that imports rclpy by name.

``modules(context)`` gives ``rclpy``, ``rclpy.qos``, ``rclpy.executors``, ..., the
message packages (``sensor_msgs.msg``, ...) and the service packages (``std_srvs.srv``)
with every function bound to one mock context; ``install(context)`` puts them in
``sys.modules``, so that ``import rclpy`` in this process gets the mock (the ROS test
rig runs the bridge's ``ros`` input, and the robot's own code, unchanged on it).
"""

from __future__ import annotations

import enum
import sys
from types import ModuleType
from typing import Any

from phytrace_edge.sim.mock_ros import callback_groups, messages, qos, service_types, services
from phytrace_edge.sim.mock_ros import parameters as params
from phytrace_edge.sim.mock_ros.clock import Clock, ClockType, Time
from phytrace_edge.sim.mock_ros.executor import SingleThreadedExecutor
from phytrace_edge.sim.mock_ros.message_base import MESSAGE_TYPES
from phytrace_edge.sim.mock_ros.runtime import (
    Context,
    Node,
    SubscriptionEventCallbacks,
    default_context,
    init,
    try_shutdown,
)


class SignalHandlerOptions(enum.Enum):
    """``rclpy.signals.SignalHandlerOptions`` (the mock installs no handlers)."""

    NO = 0
    SIGINT = 1
    SIGTERM = 2
    ALL = 3


def _module(name: str, **attributes: Any) -> ModuleType:
    module = ModuleType(name)
    vars(module).update(attributes)
    return module


def modules(context: Context | None = None) -> dict[str, ModuleType]:
    """rclpy's modules (those the bridge and the test rig use) over ``context``."""
    ctx = context or default_context()

    def bound_clock(*, clock_type: ClockType = ClockType.SYSTEM_TIME) -> Clock:
        return Clock(clock_type=clock_type, source=ctx.time_source)

    def executor(*, context: Context | None = None) -> SingleThreadedExecutor:
        return SingleThreadedExecutor(context or ctx)

    found: dict[str, ModuleType] = {
        "rclpy": _module(
            "rclpy",
            init=lambda args=None, *, context=None, signal_handler_options=None: init(
                args, context=context or ctx
            ),
            create_node=lambda node_name, **kwargs: Node(node_name, context=ctx, **kwargs),
            try_shutdown=lambda *, context=None: try_shutdown(context=context or ctx),
            ok=lambda *, context=None: (context or ctx).ok(),
        ),
        "rclpy.qos": qos,
        "rclpy.clock": _module("rclpy.clock", Clock=bound_clock, ClockType=ClockType),
        "rclpy.time": _module("rclpy.time", Time=Time),
        "rclpy.event_handler": _module(
            "rclpy.event_handler", SubscriptionEventCallbacks=SubscriptionEventCallbacks
        ),
        "rclpy.signals": _module("rclpy.signals", SignalHandlerOptions=SignalHandlerOptions),
        "rclpy.executors": _module("rclpy.executors", SingleThreadedExecutor=executor),
        "rclpy.callback_groups": callback_groups,
        "rclpy.parameter": _module(
            "rclpy.parameter",
            Parameter=params.Parameter,
            parameter_value_to_python=params.parameter_value_to_python,
        ),
        "rclpy.parameter_client": _module(
            "rclpy.parameter_client", AsyncParameterClient=services.AsyncParameterClient
        ),
    }
    packages: dict[str, dict[str, Any]] = {
        "rcl_interfaces": {"ParameterDescriptor": params.ParameterDescriptor}
    }
    assert messages.Log in MESSAGE_TYPES.values()  # the message classes are declared
    for type_name, cls in MESSAGE_TYPES.items():
        package, _, name = type_name.split("/")
        packages.setdefault(package, {})[name] = cls
    for package, classes in packages.items():
        found[package] = _module(package)
        found[f"{package}.msg"] = _module(f"{package}.msg", **classes)
    service_packages: dict[str, dict[str, Any]] = {}
    assert service_types.Trigger in service_types.SERVICE_TYPES.values()  # declared
    for type_name, srv in service_types.SERVICE_TYPES.items():
        package, _, name = type_name.split("/")
        service_packages.setdefault(package, {})[name] = srv
    for package, classes in service_packages.items():
        found.setdefault(package, _module(package))
        found[f"{package}.srv"] = _module(f"{package}.srv", **classes)
    return found


def install(context: Context | None = None) -> None:
    """Make ``import rclpy`` (and the message packages) give the mock in this process."""
    sys.modules.update(modules(context))
