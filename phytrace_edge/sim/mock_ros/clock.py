"""``rclpy.clock``/``rclpy.time`` for the mock, over a real or a virtual time source.

A virtual time source lets a simulation of minutes run in milliseconds: when the
executor has nothing to do it jumps straight to the next timer instead of sleeping.
System and steady time advance together in it, so ages and stamps stay consistent.
"""

from __future__ import annotations

import enum
import threading
import time


class ClockType(enum.IntEnum):
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


class RealTimeSource:
    """The process's clocks; waiting really waits."""

    virtual = False

    def steady_ns(self) -> int:
        return time.monotonic_ns()

    def system_ns(self) -> int:
        return time.time_ns()

    def wait(self, condition: threading.Condition, until_steady_ns: int | None) -> None:
        """Wait on ``condition`` (held by the caller) until notified or the deadline."""
        timeout = None if until_steady_ns is None else max(0, until_steady_ns - self.steady_ns())
        condition.wait(None if timeout is None else timeout / 1e9)


class VirtualTimeSource:
    """Time that advances only when the executor has nothing left to do."""

    virtual = True

    def __init__(self, start_system_ns: int | None = None) -> None:
        self._steady_ns = 0
        self._start_system_ns = time.time_ns() if start_system_ns is None else start_system_ns

    def steady_ns(self) -> int:
        return self._steady_ns

    def system_ns(self) -> int:
        return self._start_system_ns + self._steady_ns

    def wait(self, condition: threading.Condition, until_steady_ns: int | None) -> None:
        if until_steady_ns is not None:
            self._steady_ns = max(self._steady_ns, until_steady_ns)


TimeSource = RealTimeSource | VirtualTimeSource


class Time:
    """A point in time of one clock type, like ``rclpy.time.Time``."""

    def __init__(
        self,
        *,
        seconds: float = 0,
        nanoseconds: int = 0,
        clock_type: ClockType = ClockType.SYSTEM_TIME,
    ) -> None:
        self.nanoseconds = int(seconds * 1e9) + nanoseconds
        self.clock_type = clock_type

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return divmod(self.nanoseconds, 1_000_000_000)

    def to_msg(self):  # -> builtin_interfaces.msg.Time
        from phytrace_edge.sim.mock_ros.messages import Time as TimeMsg

        sec, nanosec = self.seconds_nanoseconds()
        return TimeMsg(sec=sec, nanosec=nanosec)

    def __repr__(self) -> str:
        return f"Time(nanoseconds={self.nanoseconds}, clock_type={self.clock_type.name})"


class Clock:
    """``rclpy.clock.Clock``; ROS time is system time here (no /clock simulation). The
    time source is the context's (``Node.get_clock()``, ``as_rclpy``'s ``Clock``)."""

    def __init__(self, *, clock_type: ClockType = ClockType.SYSTEM_TIME, source: TimeSource):
        self.clock_type = clock_type
        self._source = source

    def now(self) -> Time:
        if self.clock_type == ClockType.STEADY_TIME:
            return Time(nanoseconds=self._source.steady_ns(), clock_type=self.clock_type)
        return Time(nanoseconds=self._source.system_ns(), clock_type=self.clock_type)
