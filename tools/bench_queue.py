"""Queue benchmark: phytrace-edge's QueueStore vs the raw-sqlite3 ceiling vs persist-queue.

    .venv/bin/pip install persist-queue        # the baseline a Python user would pick
    .venv/bin/python tools/bench_queue.py      # about 3-4 minutes
    .venv/bin/python tools/bench_queue.py --events 5000 --rss-events 100000   # quick

All three store the same events (simulated UDM events, fresh event_id each) in WAL mode
with the same synchronous setting, in fresh files on the same disk; rounds are
interleaved and the median is reported. The ceiling is plain ``executemany`` into a
table with no queue logic at all. persist-queue's SQLiteAckQueue commits every put
and two commits per delivered event: it has no grouped put or batch ack, so its
grouped rows repeat its per-event numbers.

Rows:
- put 1/txn: one event per transaction (fsync each under synchronous=FULL)
- put 100/txn: group commit of 100 events
- drain: claim 200 oldest + delete them, per transaction
- bytes/event: file size (db + wal) / events, after a checkpoint
- RSS with N queued: resident memory of a process that queued N events (subprocess)
"""

from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import orjson

from phytrace_edge import run_simulation
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.types import Built
from phytrace_edge.units import GIB

ROUNDS = 3
DRAIN_BATCH = 200
GROUP = 100


def sample_events(count: int) -> list[dict]:
    base: list[dict] = []
    run_simulation(400, sink=base.append, seed=3)
    return [{**base[i % len(base)], "event_id": str(uuid.uuid4())} for i in range(count)]


# ---------------------------------------------------------------- implementations


class Raw:
    """The ceiling: executemany into a plain table, delete by id range."""

    name = "raw sqlite3 (ceiling)"

    def __init__(self, path: Path, sync: str) -> None:
        self.db = sqlite3.connect(path, isolation_level=None)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute(f"PRAGMA synchronous={sync}")
        self.db.execute("CREATE TABLE q (id INTEGER PRIMARY KEY, body BLOB)")

    def put(self, events: list[dict]) -> None:
        rows = [(orjson.dumps(e),) for e in events]
        self.db.execute("BEGIN")
        self.db.executemany("INSERT INTO q(body) VALUES (?)", rows)
        self.db.execute("COMMIT")

    def drain(self, batch: int) -> int:
        self.db.execute("BEGIN IMMEDIATE")
        rows = self.db.execute("SELECT id, body FROM q ORDER BY id LIMIT ?", (batch,)).fetchall()
        if rows:
            self.db.execute("DELETE FROM q WHERE id <= ?", (rows[-1][0],))
        self.db.execute("COMMIT")
        return len(rows)

    def close(self) -> None:
        self.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        self.db.close()


class Ours:
    def __init__(self, path: Path, sync: str, compression: str = "zstd") -> None:
        self.name = f"phytrace-edge ({compression})"
        self.store = QueueStore.open(
            path,
            limits=QueueLimits(max_bytes=64 * GIB),
            compression=compression,
            sync=sync.lower(),
        )

    def put(self, events: list[dict]) -> None:
        if len(events) == 1:
            self.store.put(events[0])
        else:
            self.store.put_many([Built(event) for event in events])

    def drain(self, batch: int) -> int:
        claimed = self.store.claim_batch(batch, 64 * 1024 * 1024)
        if claimed is None:
            return 0
        self.store.ack(claimed)
        return len(claimed.events)

    def close(self) -> None:
        self.store.reclaim_space(force=True)
        self.store.close()


class PersistQueue:
    name = "persist-queue SQLiteAckQueue"

    def __init__(self, path: Path, sync: str) -> None:
        import persistqueue

        self.q = persistqueue.SQLiteAckQueue(str(path), auto_commit=True, multithreading=False)
        self.q._getter.execute(f"PRAGMA synchronous={sync}")
        self.q._putter.execute(f"PRAGMA synchronous={sync}")

    def put(self, events: list[dict]) -> None:
        for event in events:  # no grouped put: every put commits
            self.q.put(orjson.dumps(event))

    def drain(self, batch: int) -> int:
        taken = 0
        for _ in range(batch):
            item = self.q.get(block=False) if self.q.size else None
            if item is None:
                break
            self.q.ack(item)
            taken += 1
        self.q.clear_acked_data(keep_latest=0)
        return taken

    def close(self) -> None:
        self.q.close()


# ---------------------------------------------------------------- measurements


def measure(make: Callable[[Path], object], events: list[dict]) -> dict[str, float]:
    """One round for one implementation in a fresh directory."""
    results = {}
    workdir = Path(tempfile.mkdtemp(prefix="bench-queue-"))
    try:
        single = events[: max(200, len(events) // 10)]
        impl = make(workdir / "single.db")
        started = time.perf_counter()
        for event in single:
            impl.put([event])
        results["put 1/txn (ev/s)"] = len(single) / (time.perf_counter() - started)
        impl.close()

        impl = make(workdir / "grouped.db")
        started = time.perf_counter()
        for start in range(0, len(events), GROUP):
            impl.put(events[start : start + GROUP])
        results["put 100/txn (ev/s)"] = len(events) / (time.perf_counter() - started)
        started = time.perf_counter()
        drained = 0
        while (taken := impl.drain(DRAIN_BATCH)) > 0:
            drained += taken
        results["drain (ev/s)"] = drained / (time.perf_counter() - started)
        impl.close()

        impl = make(workdir / "size.db")
        for start in range(0, len(events), GROUP):
            impl.put(events[start : start + GROUP])
        impl.close()
        # persist-queue makes a directory at the path; the others a file and its -wal
        size = sum(
            f.stat().st_size
            for f in workdir.rglob("*")
            if f.is_file() and f.relative_to(workdir).parts[0].startswith("size.db")
        )
        results["bytes/event on disk"] = size / len(events)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return results


def rss_with_backlog(kind: str, count: int) -> float:
    """RSS in MiB of a fresh process that queued ``count`` events (run as a child)."""
    out = subprocess.run(
        [sys.executable, __file__, "--child-rss", kind, "--rss-events", str(count)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)},
    ).stdout
    return float(out.strip().splitlines()[-1])


def child_rss(kind: str, count: int) -> None:
    events = sample_events(2000)
    workdir = Path(tempfile.mkdtemp(prefix="bench-rss-"))
    try:
        impl = IMPLEMENTATIONS[kind](workdir / "q.db", "NORMAL")
        for start in range(0, count, 1000):
            chunk = [
                {**events[(start + i) % len(events)], "event_id": str(uuid.uuid4())}
                for i in range(min(1000, count - start))
            ]
            impl.put(chunk)
        impl.drain(DRAIN_BATCH)  # the sender's work with a deep backlog
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                print(int(line.split()[1]) / 1024)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


IMPLEMENTATIONS: dict[str, Callable[[Path, str], object]] = {
    "raw": Raw,
    "ours-zstd": lambda p, s: Ours(p, s, "zstd"),
    "ours-gzip": lambda p, s: Ours(p, s, "gzip"),
    "ours-none": lambda p, s: Ours(p, s, "none"),
    "persist-queue": PersistQueue,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=20000)
    parser.add_argument("--rss-events", type=int, default=1_000_000)
    parser.add_argument("--sync", choices=["FULL", "NORMAL"], default="FULL")
    parser.add_argument("--child-rss", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child_rss:
        child_rss(args.child_rss, args.rss_events)
        return

    events = sample_events(args.events)
    print(
        f"{len(events)} events of {statistics.mean(len(orjson.dumps(e)) for e in events):.0f} "
        f"B JSON, synchronous={args.sync}, {ROUNDS} interleaved rounds, medians",
        flush=True,
    )
    runs: dict[str, list[dict[str, float]]] = {kind: [] for kind in IMPLEMENTATIONS}
    for round_ in range(ROUNDS):
        for kind, make in IMPLEMENTATIONS.items():
            runs[kind].append(measure(lambda path, m=make: m(path, args.sync), events))
            print(f"  round {round_ + 1}: {kind} done", flush=True)
    table = {
        kind: {k: statistics.median(r[k] for r in rs) for k in rs[0]} for kind, rs in runs.items()
    }
    for kind in ("raw", "ours-zstd", "persist-queue"):
        print(f"  RSS with {args.rss_events} queued: {kind} ...", flush=True)
        table[kind][f"RSS with {args.rss_events:,} queued (MiB)"] = rss_with_backlog(
            kind, args.rss_events
        )
    print_table(table)


def print_table(table: dict[str, dict[str, float]]) -> None:
    ceiling = table["raw"]
    metrics = list(dict.fromkeys(k for row in table.values() for k in row))
    header = "| metric | " + " | ".join(IMPLEMENTATIONS) + " |"
    print()
    print(header)
    print("|" + "---|" * (len(IMPLEMENTATIONS) + 1))
    for metric in metrics:
        cells = []
        for kind in IMPLEMENTATIONS:
            value = table[kind].get(metric)
            if value is None:
                cells.append("–")
                continue
            ratio = value / ceiling[metric] if ceiling.get(metric) else None
            text = f"{value:,.0f}" if value >= 100 else f"{value:.1f}"
            cells.append(text if kind == "raw" or ratio is None else f"{text} ({ratio:.2f}×)")
        print(f"| {metric} | " + " | ".join(cells) + " |")
    print(
        "\n(×) = ratio to the raw-sqlite3 ceiling: higher is better for ev/s, "
        "lower for bytes and RSS"
    )


if __name__ == "__main__":
    main()
