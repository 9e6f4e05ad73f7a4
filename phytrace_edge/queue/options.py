"""The queue's limits and policies (the QUEUE_* settings)."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.queue.defaults import DEFAULT_MAX_BYTES, DEFAULT_ON_FULL, DEFAULT_TTL_S


@dataclass(frozen=True)
class QueueLimits:
    """Caps and policies (QUEUE_MAX_BYTES, QUEUE_MAX_EVENTS, QUEUE_ON_FULL, QUEUE_TTL_S)."""

    max_bytes: int = DEFAULT_MAX_BYTES
    max_events: int | None = None
    on_full: str = DEFAULT_ON_FULL
    ttl_s: float = DEFAULT_TTL_S
