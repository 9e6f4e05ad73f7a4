"""Services as ROS 2 has them, and the parameter services every node offers.

A service is advertised as soon as its node exists, but a request is answered only
when an executor that spins the server's node takes it: a node that nobody spins
looks ready to a client and never answers (``ros2 param list`` then waits forever).
``AsyncParameterClient`` is ``rclpy.parameter_client``'s, over those services.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from phytrace_edge.sim.mock_ros.callback_groups import CallbackGroup
from phytrace_edge.sim.mock_ros.parameters import Parameter

if TYPE_CHECKING:
    from phytrace_edge.sim.mock_ros.runtime import Context, Node

PARAMETER_SERVICES = ("describe_parameters", "get_parameters", "list_parameters", "set_parameters")


class Future:
    """``rclpy.task.Future``: done once its result is set (by the server's executor)."""

    def __init__(self, condition: threading.Condition) -> None:
        self._condition = condition
        self._done = False
        self._result: Any = None

    def done(self) -> bool:
        return self._done

    def result(self) -> Any:
        return self._result

    def set_result(self, result: Any) -> None:
        with self._condition:
            self._result, self._done = result, True
            self._condition.notify_all()


@dataclass(eq=False)
class Service:
    """A service of a node: requests wait in ``pending`` for an executor."""

    name: str
    handler: Callable[[Any], Any]
    callback_group: CallbackGroup
    pending: deque[tuple[Any, Future]] = field(default_factory=deque)


def parameter_services(node: Node, group: CallbackGroup) -> list[Service]:
    """``describe/get/list/set_parameters`` of ``node``, answered from its parameters."""

    def declared(names: list[str]) -> list[str]:
        """rclpy answers nothing at all when one of the names is not declared."""
        return names if all(node.has_parameter(name) for name in names) else []

    handlers: dict[str, Callable[[Any], Any]] = {
        "describe_parameters": lambda request: SimpleNamespace(
            descriptors=[node.describe_parameter(name) for name in declared(request.names)]
        ),
        "get_parameters": lambda request: SimpleNamespace(
            values=[
                node.get_parameter(name).get_parameter_value() for name in declared(request.names)
            ]
        ),
        "list_parameters": lambda request: SimpleNamespace(
            result=SimpleNamespace(names=list(node.parameter_names()), prefixes=[])
        ),
        "set_parameters": lambda request: SimpleNamespace(
            results=[node.set_parameter(parameter) for parameter in request.parameters]
        ),
    }
    fqn = node.get_fully_qualified_name()
    return [Service(f"{fqn}/{kind}", handlers[kind], group) for kind in PARAMETER_SERVICES]


def call(context: Context, service_name: str, request: Any) -> Future:
    """Send ``request``; a service nobody offers never answers, as in DDS."""
    future = Future(context.condition)
    with context.condition:
        for node in context.nodes:
            for service in node.services:
                if service.name == service_name:
                    service.pending.append((request, future))
        context.condition.notify_all()
    return future


class AsyncParameterClient:
    """``rclpy.parameter_client.AsyncParameterClient``: another node's parameters."""

    def __init__(self, node: Node, remote_node_name: str) -> None:
        self._context = node.context
        self._remote = (
            remote_node_name if remote_node_name.startswith("/") else "/" + remote_node_name
        )

    def services_are_ready(self) -> bool:
        offered = {s.name for n in self._context.nodes for s in n.services}
        return all(f"{self._remote}/{kind}" in offered for kind in PARAMETER_SERVICES)

    def wait_for_services(self, timeout_sec: float | None = None) -> bool:
        deadline = None if timeout_sec is None else time.monotonic() + timeout_sec
        with self._context.condition:
            while not self.services_are_ready():
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._context.condition.wait(left)
        return True

    def list_parameters(
        self, prefixes: Sequence[str] | None = None, depth: int | None = None
    ) -> Future:
        return self._call("list_parameters", prefixes=list(prefixes or []), depth=depth or 0)

    def get_parameters(self, names: Sequence[str]) -> Future:
        return self._call("get_parameters", names=list(names))

    def describe_parameters(self, names: Sequence[str]) -> Future:
        return self._call("describe_parameters", names=list(names))

    def set_parameters(self, parameters: Sequence[Parameter]) -> Future:
        return self._call("set_parameters", parameters=list(parameters))

    def _call(self, kind: str, **request: Any) -> Future:
        return call(self._context, f"{self._remote}/{kind}", SimpleNamespace(**request))
