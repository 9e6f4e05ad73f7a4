"""The queue's limits and policies (the QUEUE_* settings)."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.queue.defaults import DEFAULT_MAX_BYTES, DEFAULT_ON_FULL, DEFAULT_TTL_S, OnFull


@dataclass(frozen=True)
class QueueLimits:
    """Caps and policies (QUEUE_MAX_BYTES, QUEUE_MAX_EVENTS, QUEUE_ON_FULL, QUEUE_TTL_S)."""

    max_bytes: int = DEFAULT_MAX_BYTES
    max_events: int | None = None
    on_full: OnFull | str = DEFAULT_ON_FULL  # the setting's text is read as an OnFull
    ttl_s: float = DEFAULT_TTL_S

    def __post_init__(self) -> None:
        object.__setattr__(self, "on_full", OnFull(self.on_full))

    @property
    def makes_room(self) -> bool:
        """Whether a full queue makes room for what comes in (thins or drops the
        oldest) rather than refusing it (drop_newest)."""
        return self.on_full is not OnFull.DROP_NEWEST
