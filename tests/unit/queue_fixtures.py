"""What the queue's tests share: a settable clock, numbered events, and a store
opener (the ``clock`` and ``open_store`` fixtures live in ``conftest.py``)."""

from __future__ import annotations

import contextlib
import sqlite3
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import orjson

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB


class Clock:
    def __init__(self) -> None:
        self.now = 1_800_000_000.0

    def __call__(self) -> float:
        return self.now


def event(n: int, pad: int = 0) -> dict:
    return {
        "event_id": str(uuid.UUID(int=n)),
        "event_type": "telemetry.periodic",
        "seq": n,
        "note": "x" * pad,
    }


def store_opener(tmp_path: Path, clock: Clock) -> Iterator[Callable[..., QueueStore]]:
    """Opens stores under ``tmp_path/state`` on ``clock``; closes them all after."""
    opened: list[QueueStore] = []

    def make(name: str = "queue.db", **kwargs: object) -> QueueStore:
        limits = kwargs.pop("limits", QueueLimits(max_bytes=64 * MIB))
        store = QueueStore.open(tmp_path / "state" / name, limits=limits, clock=clock, **kwargs)
        opened.append(store)
        return store

    yield make
    for store in opened:
        with contextlib.suppress(sqlite3.ProgrammingError):  # closed by the test
            store.close()


def seqs(batch) -> list[int]:
    return [orjson.loads(e.json)["seq"] for e in batch.events]
