"""The handler of ``/rosout`` (``rcl_interfaces/msg/Log``): a ROS log record -> reading,
pure like the other handlers. The builder turns readings into ``log.record`` events."""

from __future__ import annotations

from typing import Any, cast

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import integer, present, text
from phytrace_edge.ingest.readings import (
    LogReading,
)

MESSAGE_MAX_CHARS = 2048
# rcl_interfaces/msg/Log.DEBUG ... FATAL; rcutils also uses the values in between
LEVELS = ((50, "fatal"), (40, "error"), (30, "warn"), (20, "info"), (10, "debug"))


def level_name(level: int) -> str:
    """A Log level as its name; a value between two levels counts as the lower one."""
    return next((name for floor, name in LEVELS if level >= floor), "debug")


def handle_log(msg: Any) -> LogReading:
    """``rcl_interfaces/msg/Log`` -> ``{level, logger, message, file, function, line,
    stamp_ns}``; a record without a level or a logger name is malformed."""
    level = integer(getattr(msg, "level", None))
    logger = text(getattr(msg, "name", None))
    if level is None or not logger:
        raise MalformedMessage("not_a_log_record", f"level={level!r} name={logger!r}")
    message = getattr(msg, "msg", "")
    stamp = getattr(msg, "stamp", None)
    seconds = integer(getattr(stamp, "sec", None)) or 0
    nanos = integer(getattr(stamp, "nanosec", None)) or 0
    line = integer(getattr(msg, "line", None))
    return cast(
        LogReading,
        present(
            level=level_name(level),
            logger=logger,
            message=message[:MESSAGE_MAX_CHARS] if isinstance(message, str) else "",
            file=text(getattr(msg, "file", None)) or None,
            function=text(getattr(msg, "function", None)) or None,
            line=line if line else None,
            stamp_ns=seconds * 1_000_000_000 + nanos or None,
        ),
    )
