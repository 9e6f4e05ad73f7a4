"""The queue's limits and policies, and their defaults (the QUEUE_* settings)."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.units import GIB

DEFAULT_MAX_BYTES = 1 * GIB
DEFAULT_TTL_S = 7 * 24 * 3600.0
DEFAULT_LEASE_S = 60.0
DEFAULT_BUSY_TIMEOUT_S = 5.0
ON_FULL_POLICIES = ("drop_oldest", "drop_newest")
COMPRESSIONS = ("zstd", "gzip", "none")
SYNC_MODES = ("full", "normal")
DEFAULT_ON_FULL = "drop_oldest"
DEFAULT_COMPRESSION = "zstd"
DEFAULT_SYNC = "full"  # cheap with group commit (MEASUREMENTS.md)


@dataclass(frozen=True)
class QueueLimits:
    """Caps and policies (QUEUE_MAX_BYTES, QUEUE_MAX_EVENTS, QUEUE_ON_FULL, QUEUE_TTL_S)."""

    max_bytes: int = DEFAULT_MAX_BYTES
    max_events: int | None = None
    on_full: str = DEFAULT_ON_FULL
    ttl_s: float = DEFAULT_TTL_S
