"""The queue's value types: what goes in and what comes out."""

from __future__ import annotations

from dataclasses import dataclass


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
