"""Defaults and choices of the sending settings (plain constants: the configuration
reads them without importing the stage)."""

from phytrace_edge.units import MIB

DEFAULT_ENDPOINT = "http://localhost:8000/api/v1"
DEFAULT_BATCH_SIZE = 10
DEFAULT_BACKLOG_BATCH_SIZE = 500  # docs/benchmarks.md: 500 reaches the link's ceiling
DEFAULT_REQUESTS_IN_FLIGHT = 2  # docs/benchmarks.md: 2 hides a cellular round trip
DEFAULT_LIVE_SHARE = 0.2  # of the requests while a backlog drains: the newest events first
DEFAULT_IMPORTANT_FIRST = True
DEFAULT_BATCH_MAX_BYTES = 1 * MIB
DEFAULT_FLUSH_INTERVAL_S = 2.0
DEFAULT_RETRY_MIN_S = 0.5
DEFAULT_RETRY_MAX_S = 60.0
DEFAULT_HTTP_TIMEOUT_S = 10.0
HTTP_COMPRESSIONS = ("gzip", "zstd", "none")
DEFAULT_HTTP_COMPRESSION = "gzip"
