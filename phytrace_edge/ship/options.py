"""How batches are formed, sent and retried (the send policy)."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.ship.defaults import (
    DEFAULT_BACKLOG_BATCH_SIZE,
    DEFAULT_BATCH_MAX_BYTES,
    DEFAULT_BATCH_SIZE,
    DEFAULT_FLUSH_INTERVAL_S,
    DEFAULT_HTTP_COMPRESSION,
    DEFAULT_IMPORTANT_FIRST,
    DEFAULT_LIVE_SHARE,
    DEFAULT_REQUESTS_IN_FLIGHT,
    DEFAULT_RETRY_MAX_S,
    DEFAULT_RETRY_MIN_S,
)


@dataclass(frozen=True)
class SendPolicy:
    """BATCH_SIZE, BACKLOG_BATCH_SIZE, BATCH_MAX_BYTES, REQUESTS_IN_FLIGHT, LIVE_SHARE,
    BACKFILL_IMPORTANT_FIRST, FLUSH_INTERVAL_S, RETRY_MIN_S/MAX_S, HTTP_COMPRESSION
    and UPLOAD_MAX_BPS."""

    batch_size: int = DEFAULT_BATCH_SIZE
    backlog_batch_size: int = DEFAULT_BACKLOG_BATCH_SIZE
    requests_in_flight: int = DEFAULT_REQUESTS_IN_FLIGHT
    live_share: float = DEFAULT_LIVE_SHARE
    important_first: bool = DEFAULT_IMPORTANT_FIRST
    batch_max_bytes: int = DEFAULT_BATCH_MAX_BYTES
    flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S
    retry_min_s: float = DEFAULT_RETRY_MIN_S
    retry_max_s: float = DEFAULT_RETRY_MAX_S
    http_compression: str = DEFAULT_HTTP_COMPRESSION
    upload_max_bps: int | None = None


MIN_LEASE_S = 60.0


def claim_lease_s(policy: SendPolicy, http_timeout_s: float) -> float:
    """How long a claimed batch stays a sender's: longer than the longest retry wait
    plus a request, twice over, so a batch still being retried is never taken by a
    second sender (an operator's ``drain`` beside the service)."""
    return max(MIN_LEASE_S, 2 * (policy.retry_max_s + http_timeout_s))
