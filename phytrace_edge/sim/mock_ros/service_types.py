"""The mock service types, as rosidl_generator_py makes them: a class per service with
``Request`` and ``Response`` message classes (``std_srvs.srv.Trigger.Request()``,
``Trigger.Response(success=False, message='')``), whose fields follow the same rules
as the messages' (``message_base``). ``as_rclpy.modules`` puts them in ``<package>.srv``.
"""

from __future__ import annotations

from typing import Any, ClassVar

from phytrace_edge.sim.mock_ros.message_base import Message, declare

SERVICE_TYPES: dict[str, type[ServiceType]] = {}


class ServiceType:
    """A service type: its request and response classes (rclpy's ``Metaclass_X``
    classes carry them the same way)."""

    Request: ClassVar[type[Message]]
    Response: ClassVar[type[Message]]
    _type: ClassVar[str]


def declare_service(
    type_name: str, request: dict[str, str], response: dict[str, str], **extra: Any
) -> type[ServiceType]:
    """One service type, e.g. ``declare_service("std_srvs/srv/Trigger", {}, {...})``."""
    name = type_name.split("/")[-1]
    namespace = {
        "_type": type_name,
        "Request": declare(f"{type_name}_Request", request),
        "Response": declare(f"{type_name}_Response", response),
        **extra,
    }
    service: type[ServiceType] = type(name, (ServiceType,), namespace)
    SERVICE_TYPES[type_name] = service
    return service


Trigger = declare_service("std_srvs/srv/Trigger", {}, {"success": "boolean", "message": "string"})
