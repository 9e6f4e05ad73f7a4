"""A node's logger, as rcl's logging: each record goes to ``/rosout`` as an
rcl_interfaces/msg/Log, from the node's name."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from phytrace_edge.sim.mock_ros.messages import Log
from phytrace_edge.sim.mock_ros.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

if TYPE_CHECKING:
    from phytrace_edge.sim.mock_ros.runtime import Node

# rcl's /rosout publisher: reliable, transient local, the last 1000 records
ROSOUT_QOS = QoSProfile(
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

DEBUG, INFO, WARN, ERROR, FATAL = 10, 20, 30, 40, 50  # rcl_interfaces/msg/Log's levels


class NodeLogger:
    """A node's logger: each record goes to ``/rosout`` as an rcl_interfaces/msg/Log,
    as rcl's logging does (levels as in that message)."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self._rosout: Any = None

    def _log(self, level: int, message: str) -> None:
        if self._rosout is None:
            self._rosout = self._node.create_publisher(Log, "/rosout", ROSOUT_QOS)
        name = self._node.get_fully_qualified_name().lstrip("/").replace("/", ".")
        stamp = self._node.get_clock().now().to_msg()
        self._rosout.publish(
            Log(stamp=stamp, level=level, name=name, msg=message, file="", function="", line=0)
        )

    def debug(self, message: str) -> None:
        self._log(DEBUG, message)

    def info(self, message: str) -> None:
        self._log(INFO, message)

    def warning(self, message: str) -> None:
        self._log(WARN, message)

    warn = warning

    def error(self, message: str) -> None:
        self._log(ERROR, message)

    def fatal(self, message: str) -> None:
        self._log(FATAL, message)
