"""Putting plain events into a store, for tests that do not build them."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, cast

from phytrace_edge.queue.records import PutResult
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.types import Built, UdmEvent


def put_events(
    store: QueueStore,
    events: Iterable[dict[str, Any]],
    important: bool | Sequence[bool] = False,
) -> PutResult:
    """Queue ``events`` in one transaction: all of one class, or each its own."""
    listed = list(events)
    classes = [important] * len(listed) if isinstance(important, bool) else list(important)
    return store.put_many(
        [Built(cast(UdmEvent, event), cls) for event, cls in zip(listed, classes, strict=True)]
    )
