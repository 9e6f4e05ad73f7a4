"""Defaults and choices of the QUEUE_* settings (plain constants: the configuration
reads them without importing the stage)."""

from phytrace_edge.units import GIB

DEFAULT_MAX_BYTES = 1 * GIB
DEFAULT_TTL_S = 7 * 24 * 3600.0
DEFAULT_LEASE_S = 60.0
DEFAULT_BUSY_TIMEOUT_S = 5.0
ON_FULL_POLICIES = ("thin", "drop_oldest", "drop_newest")
COMPRESSIONS = ("zstd", "gzip", "none")
SYNC_MODES = ("full", "normal")
DEFAULT_ON_FULL = "thin"
DEFAULT_COMPRESSION = "zstd"
DEFAULT_SYNC = "full"  # cheap with group commit (docs/benchmarks.md, "Queue")
