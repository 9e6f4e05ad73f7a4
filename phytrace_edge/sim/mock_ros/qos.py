"""QoS profiles and the DDS request/offer compatibility rule, as ``rclpy.qos`` has them.

The rule that matters for a telemetry bridge: a subscription that *requests* more
than a publisher *offers* is incompatible and receives nothing. A RELIABLE reader gets
nothing from a BEST_EFFORT writer (typical sensor drivers), and a TRANSIENT_LOCAL
reader gets nothing from a VOLATILE writer.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class QoSPolicyKind(enum.IntEnum):
    INVALID = 1 << 0
    DURABILITY = 1 << 1
    RELIABILITY = 1 << 5


@dataclass
class QoSProfile:
    """A QoS profile; like rclpy's, ``depth`` is required with KEEP_LAST history."""

    history: HistoryPolicy = HistoryPolicy.KEEP_LAST
    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE

    def __post_init__(self) -> None:
        if self.history == HistoryPolicy.KEEP_LAST and self.depth < 1:
            raise ValueError("A QoSProfile with KEEP_LAST history needs a depth >= 1")
        if self.reliability == ReliabilityPolicy.SYSTEM_DEFAULT:
            self.reliability = ReliabilityPolicy.RELIABLE
        if self.durability == DurabilityPolicy.SYSTEM_DEFAULT:
            self.durability = DurabilityPolicy.VOLATILE


qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
qos_profile_system_default = QoSProfile()


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """rclpy accepts a bare depth wherever a profile goes."""
    return QoSProfile(depth=qos) if isinstance(qos, int) else qos


def incompatible_policy(offered: QoSProfile, requested: QoSProfile) -> QoSPolicyKind | None:
    """The policy that stops a writer (``offered``) from matching a reader, or None."""
    if (
        requested.reliability == ReliabilityPolicy.RELIABLE
        and offered.reliability == ReliabilityPolicy.BEST_EFFORT
    ):
        return QoSPolicyKind.RELIABILITY
    if (
        requested.durability == DurabilityPolicy.TRANSIENT_LOCAL
        and offered.durability == DurabilityPolicy.VOLATILE
    ):
        return QoSPolicyKind.DURABILITY
    return None
