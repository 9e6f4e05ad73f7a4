"""Queue: the durable SQLite WAL hand-off between build and ship.

``store`` owns the database (put, claim, ack, release, caps, TTL, stats), ``records``
holds its value types,
``codecs`` the at-rest encodings, ``migrate`` the schema versions, ``recovery``
opening a file safely, and ``dead_letters`` the operator's view of rejected events.
"""

from phytrace_edge.queue.records import (
    Batch,
    DeadLetter,
    PutResult,
    QueuedEvent,
    QueueLimits,
    QueueStats,
)
from phytrace_edge.queue.store import QueueStore

__all__ = [
    "Batch",
    "DeadLetter",
    "PutResult",
    "QueueLimits",
    "QueueStats",
    "QueueStore",
    "QueuedEvent",
]
