"""The ``ros`` input started once in this process, on real rclpy or (``--mock``) on the
mock installed as ``rclpy``, with std_srvs importable or (``--hide-std-srvs``) not, as
on a robot without the package; prints what came of it as one JSON line: the WARNINGs
the bridge logged, the ``~/mark`` service's name (null: none) and the topics it
subscribed. ``test_ros_incident.py`` runs it with each flavour's Python."""

from __future__ import annotations

import importlib
import json
import logging
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout


class Kept(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def service_name(node: Any, service: Any) -> str | None:
    """The service's full name: rclpy says it from Iron on (``service_name``); Humble's
    ``srv_name`` is the name as given (``~/mark``), so the node's own services say it."""
    if service is None:
        return None
    if name := getattr(service, "service_name", None):
        return str(name)
    found = node.get_service_names_and_types_by_node(node.get_name(), node.get_namespace())
    return next((name for name, _ in found if name.endswith("/mark")), None)


def main() -> int:
    if "--mock" in sys.argv:
        from phytrace_edge.sim.mock_ros import as_rclpy

        as_rclpy.install()
    hide = "--hide-std-srvs" in sys.argv

    def import_module(name: str) -> ModuleType:
        if hide and name.split(".")[0] == "std_srvs":
            raise ModuleNotFoundError("No module named 'std_srvs'", name="std_srvs")
        return importlib.import_module(name)

    from phytrace_edge.ingest.sources.base import Feed, MarkReply, SourceOptions
    from phytrace_edge.ingest.sources.ros import RosSource

    kept = Kept()
    logging.getLogger("phytrace_edge").addHandler(kept)
    source = RosSource(SourceOptions(kind="ros", topics={"/odom": "/odom"}), import_module)

    def ignore(topic: str, msg: Any, age_s: float = 0.0) -> None:
        return None

    source.start(Feed(ignore, lambda at: False, 0.2, mark=lambda reason: MarkReply(True, reason)))
    try:
        seen = {
            "warnings": kept.messages,
            "mark_service": service_name(source.node, source.mark_service),
            "subscribed": sorted(source.topic_stats()),
        }
    finally:
        source.stop()
    print(json.dumps(seen))
    return 0


if __name__ == "__main__":
    sys.exit(main())
