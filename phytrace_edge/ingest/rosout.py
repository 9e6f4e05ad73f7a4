"""The handler of ``/rosout`` (``rcl_interfaces/msg/Log``): a ROS log record -> reading,
pure like the other handlers. The builder turns readings into ``log.record`` events."""

from __future__ import annotations

from typing import Any, cast

from phytrace_edge.errors import MalformedMessage
from phytrace_edge.ingest.convert import checked_text, integer, present
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
    logger, logger_repaired = checked_text(getattr(msg, "name", None))
    if level is None or not logger:
        raise MalformedMessage("not_a_log_record", f"level={level!r} name={logger!r}")
    raw_message = getattr(msg, "msg", "")
    message, message_repaired = (
        checked_text(raw_message, MESSAGE_MAX_CHARS)
        if isinstance(raw_message, str)
        else ("", False)
    )
    file, file_repaired = checked_text(getattr(msg, "file", None))
    function, function_repaired = checked_text(getattr(msg, "function", None))
    stamp = getattr(msg, "stamp", None)
    seconds = integer(getattr(stamp, "sec", None)) or 0
    nanos = integer(getattr(stamp, "nanosec", None)) or 0
    line = integer(getattr(msg, "line", None))
    repaired = logger_repaired + message_repaired + file_repaired + function_repaired
    return cast(
        LogReading,
        present(
            level=level_name(level),
            logger=logger,
            message=message,
            file=file or None,
            function=function or None,
            line=line if line else None,
            stamp_ns=seconds * 1_000_000_000 + nanos or None,
            text_repaired=repaired or None,
        ),
    )
