"""Services as ROS 2 has them, and the parameter services every node offers.

A service is advertised as soon as it is created (the parameter services: as soon as
their node exists), but a request is answered only when an executor that spins the
server's node takes it: a node that nobody spins looks ready to a client and never
answers (``ros2 param list`` then waits forever). ``Node.create_service`` calls its
callback with the request and a fresh response, and sends what it returns (a TypeError
in the server's executor when that is not the service type's response, as rclpy's
``send_response`` raises). A ``Client`` (``Node.create_client``) sends a copy of its
request; the answer reaches its future only when an executor that spins the client's
node takes it (rclpy: a client whose node nobody spins never sees its future done).
``AsyncParameterClient`` is ``rclpy.parameter_client``'s, over the parameter services;
unlike rclpy's, its futures are done as soon as the server answers (the unit tests
lean on that).
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
from phytrace_edge.sim.mock_ros.message_base import Message, wire_copy
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
    """A service of a node: requests wait in ``pending`` for an executor, each with
    its future and the client to answer through (None: the future directly)."""

    name: str  # fully qualified
    handler: Callable[[Any], Any]  # request -> response
    callback_group: CallbackGroup
    pending: deque[tuple[Any, Future, Client | None]] = field(default_factory=deque)
    srv_type: Any = None
    srv_name: str = ""  # as given to create_service ("~/mark")

    @property
    def service_name(self) -> str:
        return self.name

    def answer(self, request: Any, future: Future, client: Client | None) -> None:
        """Run the handler (in the executor that spins the server's node) and send
        its response: to the client's node, or straight into the future."""
        response = self.handler(request)
        if client is None:
            future.set_result(response)
        else:
            client.receive(response, future)


def typed_handler(srv_type: Any, callback: Callable[[Any, Any], Any]) -> Callable[[Any], Any]:
    """What ``Node.create_service`` serves: ``callback(request, srv_type.Response())``,
    checked as rclpy's ``send_response`` checks it."""

    def handler(request: Any) -> Any:
        response = callback(request, srv_type.Response())
        if not isinstance(response, srv_type.Response):
            raise TypeError(
                f"the service callback returned {type(response).__name__}, "
                f"not {srv_type.Response.__name__}"
            )
        return response

    return handler


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


def call(context: Context, service_name: str, request: Any, client: Client | None = None) -> Future:
    """Send ``request`` (through ``client``, or answered straight into the future); a
    service nobody offers never answers, as in DDS."""
    future = Future(context.condition)
    with context.condition:
        for node in context.nodes:
            for service in node.services:
                if service.name == service_name:
                    sent = wire_copy(request) if isinstance(request, Message) else request
                    service.pending.append((sent, future, client))
        context.condition.notify_all()
    return future


def offered(context: Context, service_name: str) -> bool:
    """Whether a node of the graph offers ``service_name`` (caller holds the condition)."""
    return any(s.name == service_name for n in context.nodes for s in n.services)


class Client:
    """``rclpy.client.Client``: calls one service; the answers wait in ``responses``
    for an executor that spins the client's node."""

    def __init__(
        self, node: Node, srv_type: Any, srv_name: str, service_name: str, group: CallbackGroup
    ) -> None:
        self.node, self.srv_type, self.srv_name = node, srv_type, srv_name
        self.service_name = service_name  # fully qualified
        self.callback_group = group
        self.responses: deque[tuple[Any, Future]] = deque()
        self.destroyed = False

    def service_is_ready(self) -> bool:
        with self.node.context.condition:
            return offered(self.node.context, self.service_name)

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        context = self.node.context
        deadline = None if timeout_sec is None else time.monotonic() + timeout_sec
        with context.condition:
            while not offered(context, self.service_name):
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return False
                context.condition.wait(left)
        return True

    def call_async(self, request: Any) -> Future:
        if not isinstance(request, self.srv_type.Request):
            raise TypeError(
                f"Expected {self.srv_type.Request.__name__}, got {type(request).__name__}"
            )
        return call(self.node.context, self.service_name, request, self)

    def receive(self, response: Any, future: Future) -> None:
        """The server's answer reaches the client's node (a destroyed client's is lost)."""
        context = self.node.context
        with context.condition:
            if not self.destroyed:
                self.responses.append((wire_copy(response), future))
                context.condition.notify_all()


class AsyncParameterClient:
    """``rclpy.parameter_client.AsyncParameterClient``: another node's parameters."""

    def __init__(self, node: Node, remote_node_name: str) -> None:
        self._context = node.context
        self._remote = (
            remote_node_name if remote_node_name.startswith("/") else "/" + remote_node_name
        )

    def services_are_ready(self) -> bool:
        return all(offered(self._context, f"{self._remote}/{kind}") for kind in PARAMETER_SERVICES)

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
