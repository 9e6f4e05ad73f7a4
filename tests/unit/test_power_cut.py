"""What a power cut can leave behind, found on LazyFS (a file system that drops what
was not fsynced): the files are made here in the states it left them in."""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

import pytest

from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.space.reserve import SpaceReserve
from phytrace_edge.queue.store import QueueStore
from tests.processes import run_cli
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event


@pytest.fixture
def clock() -> Clock:
    return Clock()


def cut_before_the_first_commit(path: Path) -> None:
    """A queue file as a cut before the first checkpoint leaves it: page 1 of a WAL
    database (4 KiB, no tables) and a WAL holding only its 32-byte header."""
    path.parent.mkdir(parents=True, exist_ok=True)
    made = sqlite3.connect(path)
    made.execute("PRAGMA journal_mode = WAL")
    made.close()
    scratch = path.with_name("scratch.db")
    other = sqlite3.connect(scratch)
    other.execute("PRAGMA journal_mode = WAL")
    other.execute("CREATE TABLE t (x)")  # a WAL with a header and frames
    header = Path(f"{scratch}-wal").read_bytes()[:32]
    other.close()
    Path(f"{path}-wal").write_bytes(header)  # the frames were never synced
    assert path.stat().st_size == 4096


def test_status_and_run_both_see_an_empty_queue_after_a_cut_before_the_first_commit(
    tmp_path: Path, clock: Clock
) -> None:
    path = tmp_path / "queue.db"
    cut_before_the_first_commit(path)
    stats = read_stats(str(path))
    assert stats is not None
    assert (stats.depth, stats.queued_total, stats.drops, stats.service) == (0, 0, {}, None)
    result = run_cli("status", QUEUE_PATH=str(path))
    assert result.returncode == 3, result.stderr  # not running, not "not a queue" (4)
    assert result.stderr == ""
    lines = result.stdout.splitlines()
    assert lines[:2] == [
        "phytrace-edge status: NOT RUNNING",
        "  service      never ran with this queue",
    ]
    held = rf"  queue        0 event\(s\), 0 B held of .+  {re.escape(str(path))}"
    assert re.fullmatch(held, lines[2]), lines[2]
    balance = "built 0 = delivered 0 + queued 0 + dead-lettered 0 + dropped 0 + in memory 0"
    assert f"  accounting   {balance}" in lines
    store = QueueStore.open(path, clock=clock)  # run: the same empty queue, now with tables
    try:
        assert store.stats().depth == 0
        put_events(store, [event(1)])
        assert store.stats().depth == 1
    finally:
        store.close()


def test_a_reserve_emptied_by_a_cut_is_not_held_and_is_made_again(tmp_path: Path) -> None:
    reserve = SpaceReserve(tmp_path / "queue.db", 256 * 1024)
    assert not reserve.held()
    assert reserve.restore()
    assert reserve.path.stat().st_size == 256 * 1024
    reserve.path.write_bytes(b"")  # created, its blocks never synced
    assert not reserve.held()
    assert reserve.restore()
    assert reserve.held()
    assert reserve.path.stat().st_size == 256 * 1024


def test_opening_the_queue_makes_a_short_reserve_whole(tmp_path: Path, clock: Clock) -> None:
    path = tmp_path / "queue.db"
    QueueStore.open(path, clock=clock).close()
    reserve = Path(f"{path}-reserve")
    size = reserve.stat().st_size
    assert size > 0
    reserve.write_bytes(b"")
    QueueStore.open(path, clock=clock).close()
    assert reserve.stat().st_size == size
