"""The queue's value types: what goes in, what comes out, what it reports."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.config import DEFAULT_QUEUE_TTL_S


@dataclass(frozen=True)
class QueueLimits:
    """Caps and policies (QUEUE_MAX_BYTES, QUEUE_MAX_EVENTS, QUEUE_ON_FULL, QUEUE_TTL_S)."""

    max_bytes: int
    max_events: int | None = None
    on_full: str = "drop_oldest"
    ttl_s: float = DEFAULT_QUEUE_TTL_S


@dataclass(frozen=True)
class QueuedEvent:
    """One event as the sender gets it: its row id, UDM event_id and JSON."""

    id: int
    event_id: str
    json: bytes


@dataclass(frozen=True)
class Batch:
    """Events claimed under one lease: rows ``first_id..last_id``, oldest first."""

    first_id: int
    last_id: int
    owner: str
    events: list[QueuedEvent]

    @property
    def json_bytes(self) -> int:
        return sum(len(event.json) for event in self.events)


@dataclass(frozen=True)
class PutResult:
    accepted: int
    dropped: int


@dataclass(frozen=True)
class DeadLetter:
    """An event of a batch that PhyCloud rejected for good, and why."""

    queue_id: int
    reason: str
    status_code: int | None = None
    response: str | None = None


@dataclass(frozen=True)
class QueueStats:
    """What ``status`` shows about the queue; cheap to read while the bridge writes."""

    path: str
    depth: int
    stored_bytes: int
    file_bytes: int
    oldest_queued_at: float | None
    newest_queued_at: float | None
    drops: dict[str, int]
    dead_letters: int
    queued_total: int
    acked_total: int
    leased: int
    max_bytes: int = 0
    quarantined: str | None = None
