"""Defaults and choices of the QUEUE_* settings (plain constants: the configuration
reads them without importing the stage)."""

import enum

from phytrace_edge.units import GIB


class OnFull(str, enum.Enum):
    """QUEUE_ON_FULL: what a full queue gives up first."""

    THIN = "thin"  # halve the oldest periodic history, then drop the oldest (periodic first)
    DROP_OLDEST = "drop_oldest"
    DROP_NEWEST = "drop_newest"  # refuse what comes in


DEFAULT_MAX_BYTES = 1 * GIB
DEFAULT_TTL_S = 7 * 24 * 3600.0
DEFAULT_LEASE_S = 60.0
DEFAULT_BUSY_TIMEOUT_S = 5.0
ON_FULL_POLICIES = tuple(policy.value for policy in OnFull)
COMPRESSIONS = ("zstd", "gzip", "none")
SYNC_MODES = ("full", "normal")
DEFAULT_ON_FULL = OnFull.THIN.value
DEFAULT_COMPRESSION = "zstd"
DEFAULT_SYNC = "full"  # cheap with group commit (docs/benchmarks.md, "Queue")
