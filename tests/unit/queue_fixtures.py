"""What the queue's tests share: a settable clock, a machine whose wall clock steps,
numbered and stamped events, and a store opener (the ``clock`` and ``open_store``
fixtures live in ``conftest.py``)."""

from __future__ import annotations

import contextlib
import sqlite3
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import orjson

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.queue.timekeeping.clock import Instant
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.units import MIB

Y2001 = 978_307_200.0  # 2001-01-01T00:00:00Z: where a Raspberry Pi without RTC starts
NOW = 1_795_000_000.0  # late 2026


@dataclass
class Machine:
    """A machine's clocks: a wall clock that steps, CLOCK_BOOTTIME that does not."""

    wall: float
    since_boot: float = 12.0
    boot_id: str = "boot-1"
    synchronized: bool = False

    def read(self) -> Instant:
        return Instant(self.wall, self.since_boot, self.boot_id, self.synchronized)

    def now_since_boot(self) -> float:
        return self.since_boot

    def now_wall(self) -> float:
        return self.wall

    def run(self, seconds: float) -> None:
        self.wall += seconds
        self.since_boot += seconds

    def reboot(self, wall: float, synchronized: bool) -> None:
        """Off for a while (which only a true wall clock can tell), then up again 8 s
        with the wall clock at ``wall``."""
        self.boot_id = f"{self.boot_id}+"
        self.since_boot = 8.0
        self.wall = wall
        self.synchronized = synchronized


def stamped(n: int, machine: Machine) -> dict:
    """An event as the builder stamps it on this machine's wall clock (marked when the
    kernel calls the clock unsynchronized)."""
    stamp = {**event(n), "captured_at": format_timestamp(machine.wall)}
    if not machine.synchronized:
        stamp["wall_clock"] = {"synchronized": False}
    return stamp


def put_stamped(store: QueueStore, machine: Machine, seqs_: range) -> None:
    for n in seqs_:
        machine.run(0.2)
        store.put(stamped(n, machine))


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
