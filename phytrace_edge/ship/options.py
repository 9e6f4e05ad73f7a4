"""How batches are formed, sent and retried, and the defaults of those settings."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.units import MIB

DEFAULT_ENDPOINT = "http://localhost:8000/api/v1"
DEFAULT_BATCH_SIZE = 10
DEFAULT_BATCH_MAX_BYTES = 1 * MIB
DEFAULT_FLUSH_INTERVAL_S = 2.0
DEFAULT_RETRY_MIN_S = 0.5
DEFAULT_RETRY_MAX_S = 60.0
DEFAULT_HTTP_TIMEOUT_S = 10.0
HTTP_COMPRESSIONS = ("gzip", "zstd", "none")
DEFAULT_HTTP_COMPRESSION = "gzip"


@dataclass(frozen=True)
class SendPolicy:
    """BATCH_SIZE, BATCH_MAX_BYTES, FLUSH_INTERVAL_S, RETRY_MIN_S/MAX_S,
    HTTP_COMPRESSION and UPLOAD_MAX_BPS."""

    batch_size: int = DEFAULT_BATCH_SIZE
    batch_max_bytes: int = DEFAULT_BATCH_MAX_BYTES
    flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S
    retry_min_s: float = DEFAULT_RETRY_MIN_S
    retry_max_s: float = DEFAULT_RETRY_MAX_S
    http_compression: str = DEFAULT_HTTP_COMPRESSION
    upload_max_bps: int | None = None
