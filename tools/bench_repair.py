"""Repair after a clock step: a day's backlog stamped on an unsynchronized clock,
then NTP steps it by 25 years. How long the repair takes, how long any one look at
the clocks holds the thread that looks (the heartbeat's), and how much WAL it leaves,
side by side with draining the same backlog (the baseline: what a day's backlog costs
to send anyway).

    .venv/bin/python tools/bench_repair.py                 # a day at 5 Hz, ~1 minute
    .venv/bin/python tools/bench_repair.py --events 18000  # an hour

The machine's clocks are stood in for (the wall clock steps, CLOCK_BOOTTIME does not),
on a real queue file; events are the simulator's, stamped 0.2 s apart.
"""

from __future__ import annotations

import argparse
import contextlib
import sqlite3
import sys
import tempfile
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from phytrace_edge import run_simulation
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.queue.timekeeping.repair import pending_repair
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.udm.types import Built
from phytrace_edge.units import GIB, MIB
from tests.unit.queue_fixtures import NOW, Y2001, Machine

TICK_S = 0.2


def fill(store: QueueStore, machine: Machine, count: int) -> None:
    """``count`` events as the bridge queues them: a tick each, a second per commit."""
    samples: list[dict] = []
    run_simulation(50, sink=samples.append, seed=3)
    for start in range(0, count, 5):
        group = []
        for n in range(start, min(start + 5, count)):
            machine.run(TICK_S)
            stamp = {"captured_at": format_timestamp(machine.wall)}
            group.append({**samples[n % len(samples)], **stamp, "event_id": str(uuid.uuid4())})
            group[-1]["wall_clock"] = {"synchronized": False}
        store.put_many([Built(event) for event in group])
        if start % 10_000 == 0:
            store.record_clocks()  # the heartbeat's looks


def repairing(path: Path) -> bool:
    with contextlib.closing(sqlite3.connect(path)) as connection:
        return pending_repair(connection.cursor()) is not None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--events", type=int, default=432_000, help="a day at 5 Hz")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench-repair-"))
    machine = Machine(wall=Y2001)
    limits = QueueLimits(max_bytes=4 * GIB)
    store = QueueStore.open(folder / "queue.db", limits=limits, clocks=machine)  # type: ignore[arg-type]
    store.record_clocks()
    fill(store, machine, args.events)
    store.maintain()
    size = store.file_bytes()
    machine.wall += NOW - Y2001  # NTP
    machine.run(1.0)
    looks: list[float] = []
    started = time.perf_counter()
    while not looks or repairing(folder / "queue.db"):
        look = time.perf_counter()
        store.record_clocks()
        looks.append(time.perf_counter() - look)
    repair_s = time.perf_counter() - started
    wal = (folder / "queue.db-wal").stat().st_size
    started = time.perf_counter()
    drained = 0
    while (batch := store.claim_batch(500, 4 * MIB, important_first=False)) is not None:
        drained += len(batch.events)
        store.ack(batch)
    drain_s = time.perf_counter() - started
    store.close()
    print(f"{args.events:,} events, {size / MIB:.1f} MiB queued (frames, zstd)")
    longest = max(looks)
    print(f"repair: {repair_s:.2f} s in {len(looks)} looks, longest {longest:.2f} s")
    print(f"WAL after the repair: {wal / MIB:.1f} MiB")
    print(f"drain of the same backlog (baseline): {drain_s:.2f} s for {drained:,} events")
    print(f"repair / drain: {repair_s / drain_s:.1f}x")


if __name__ == "__main__":
    main()
