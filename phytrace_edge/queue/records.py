"""The queue's value types: what goes in and what comes out."""

from __future__ import annotations

from dataclasses import dataclass

# an incident's part, in the ``important`` column (migrations/0007_incidents.sql)
INCIDENT_CLASS = 2


@dataclass(frozen=True)
class QueuedEvent:
    """One event as the sender gets it: its queue id, UDM event_id, JSON, and when it
    was queued (a frame's events: when the frame's first was)."""

    id: int
    event_id: str
    json: bytes
    queued_at: float = 0.0


@dataclass(frozen=True)
class Batch:
    """Events claimed under one claim token (``owner``): the rows within the id
    ``ranges`` it leased (one, or one per important event taken ahead of its turn),
    oldest first."""

    ranges: tuple[tuple[int, int], ...]
    owner: str
    events: list[QueuedEvent]
    claimed_at: float = 0.0  # queue time

    @property
    def first_id(self) -> int:
        return self.ranges[0][0]

    @property
    def last_id(self) -> int:
        return self.ranges[-1][1]

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
class DeadLetterRow:
    """A dead letter as it is stored: the event encoded again on its own."""

    queue_id: int
    event_id: str
    queued_at: float
    reason: str
    status_code: int | None
    response: str | None
    codec: int
    dict_id: int | None
    json_size: int
    body: bytes
