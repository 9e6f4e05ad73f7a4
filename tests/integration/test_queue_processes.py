"""The queue across real processes: kill -9 mid-put, two drainers, memory with a backlog."""

from __future__ import annotations

import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
import uuid
from pathlib import Path

import orjson
import pytest

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import GIB
from tests.queue_events import put_events

WORKER = str(Path(__file__).with_name("queue_worker.py"))
ROOT = str(Path(__file__).parents[2])
KILLS = 20


def spawn(*args: str, **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": ROOT}
    return subprocess.Popen([sys.executable, WORKER, *args], env=env, **kwargs)


def read_acknowledged(child: subprocess.Popen, wanted: int, deadline: float) -> list[int]:
    """Seqs the child printed, reading until ``wanted`` of them or the deadline."""
    seqs = []
    while len(seqs) < wanted and time.monotonic() < deadline:
        line = child.stdout.readline()
        if not line:
            break
        seqs.append(int(line))
    return seqs


def test_acknowledged_puts_survive_kill_9(tmp_path: Path) -> None:
    path = tmp_path / "queue.db"
    rng = random.Random(1234)
    acknowledged: set[int] = set()
    start = 0
    for _ in range(KILLS):
        child = spawn("put", str(path), str(start), stdout=subprocess.PIPE, text=True)
        try:
            seqs = read_acknowledged(child, rng.randint(1, 60), time.monotonic() + 30)
            os.kill(child.pid, signal.SIGKILL)  # at a random point of the put loop
            child.wait(timeout=10)
            seqs += [int(line) for line in child.stdout.read().split()]  # printed before death
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        assert seqs, "the child acknowledged nothing"
        acknowledged.update(seqs)
        start = max(seqs) + 1

        check = sqlite3.connect(path)
        assert check.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        check.close()
        store = QueueStore.open(path, limits=QueueLimits(max_bytes=GIB))
        rows = store._db.read("SELECT codec, dict_id, body FROM events")
        queued = {orjson.loads(store.codecs.decode(*row))["seq"] for row in rows}
        assert store.stats().depth == len(rows)  # the counters survived the kill too
        store.close()
        assert acknowledged <= queued, f"lost after kill: {sorted(acknowledged - queued)[:10]}"


def test_two_processes_drain_each_event_exactly_once(tmp_path: Path) -> None:
    path = tmp_path / "queue.db"
    store = QueueStore.open(path, limits=QueueLimits(max_bytes=GIB))
    total = 5000
    for start in range(0, total, 500):
        put_events(
            store,
            [{"event_id": str(uuid.UUID(int=i)), "seq": i} for i in range(start, start + 500)],
        )
    store.close()
    outs = [tmp_path / "a.txt", tmp_path / "b.txt"]
    children = [
        spawn(
            "drain", str(path), str(out), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        for out in outs
    ]
    try:
        for child in children:
            assert child.stdout.readline().strip() == "ready"
        for child in children:
            child.stdin.write("go\n")
            child.stdin.flush()
        for child in children:
            assert child.wait(timeout=90) == 0
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait()
    a, b = ([int(x) for x in out.read_text().split()] for out in outs)
    assert len(a) + len(b) == total, "an event was delivered twice or not at all"
    assert sorted(a + b) == list(range(total))
    assert a and b, "both processes should have taken part"


@pytest.mark.slow
def test_memory_does_not_grow_with_the_backlog(tmp_path: Path) -> None:
    child = spawn("rss", str(tmp_path / "queue.db"), "200000", stdout=subprocess.PIPE, text=True)
    try:
        out, _ = child.communicate(timeout=240)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    result = orjson.loads(out)
    assert result["depth"] == 200000 - 10 * 500
    growth_mib = (result["after_kib"] - result["before_kib"]) / 1024
    # SQLite's page cache is capped at 8 MiB; 200k events are ~80 MiB on disk
    assert growth_mib < 24, f"RSS grew {growth_mib:.1f} MiB with 200k events queued"
