"""A damaged queue moved aside at open (``queue/storage/recovery.py``), on real files:
the file goes aside with its -wal/-shm beside it, a second one moved aside in the same
second is kept too, the fresh queue does not inherit the old one's damage report, what
a check found is what ``status`` shows, a file that cannot be opened is one line, and a
queue checked whole at open is not read whole again at the first upkeep, and a check
that cannot read the file is never taken for one that ran out of time."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.storage import recovery
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import NOW, event, seqs

LIMITS = QueueLimits(max_bytes=64 * MIB)


def moved_aside(path: Path) -> list[Path]:
    """The files moved aside, without their -wal/-shm companions."""
    return sorted(
        p
        for p in path.parent.glob(f"{path.name}.corrupt-*")
        if not p.name.endswith(("-wal", "-shm"))
    )


def break_schema(path: Path) -> None:
    """Damage the queue's schema as a torn write of its first page could: opening it
    raises "malformed database schema" (SQLITE_CORRUPT)."""
    db = sqlite3.connect(path)
    db.execute("PRAGMA writable_schema = ON")
    db.execute("UPDATE sqlite_master SET sql = 'CREATE TABLE counters(' WHERE name = 'counters'")
    db.commit()
    db.close()


def null_an_event_id(path: Path) -> None:
    """Damage that ``PRAGMA quick_check`` finds and reading the stats does not: a NULL
    in a NOT NULL column of one event (written with the constraint lifted a moment)."""
    db = sqlite3.connect(path, isolation_level=None)
    (sql,) = db.execute("SELECT sql FROM sqlite_master WHERE name = 'events'").fetchone()
    loose = sql.replace("event_id   TEXT    NOT NULL", "event_id   TEXT")
    assert loose != sql
    db.execute("PRAGMA writable_schema = ON")
    db.execute("UPDATE sqlite_master SET sql = ? WHERE name = 'events'", (loose,))
    db.close()
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("UPDATE events SET event_id = NULL WHERE id = (SELECT min(id) FROM events)")
    db.execute("PRAGMA writable_schema = ON")
    db.execute("UPDATE sqlite_master SET sql = ? WHERE name = 'events'", (sql,))
    db.close()


def test_a_file_moved_aside_takes_its_wal_and_shm_with_it(tmp_path: Path) -> None:
    """QUEUE_PATH pointed at another application's database, which that application
    still has open: its last commits are only in its -wal file. Moved aside without
    it, the file kept for inspection lacks them, and the fresh queue would start
    beside a WAL that is not its own."""
    path = tmp_path / "queue.db"
    other = sqlite3.connect(path, isolation_level=None)
    try:
        other.execute("PRAGMA journal_mode = WAL")
        other.execute("CREATE TABLE readings(value INTEGER)")
        other.executemany("INSERT INTO readings VALUES (?)", [(n,) for n in range(20)])
        wal = Path(f"{path}-wal").read_bytes()
        assert wal and Path(f"{path}-shm").exists()
        with QueueStore.open(path, limits=LIMITS) as fresh:
            (moved,) = moved_aside(path)
            assert fresh.stats().quarantined == str(moved)
            put_events(fresh, [event(7)])
            batch = fresh.claim_batch(10, MIB)
            assert batch is not None and seqs(batch) == [7]
        assert Path(f"{moved}-wal").read_bytes() == wal
        assert Path(f"{moved}-shm").exists()
        kept = sqlite3.connect(moved)
        try:
            assert kept.execute("SELECT count(*) FROM readings").fetchone() == (20,)
        finally:
            kept.close()
    finally:
        other.close()


def test_queues_moved_aside_in_the_same_second_are_all_kept_in_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A bridge restarting in a loop on a volume that keeps damaging files moves
    several aside within one second: each must keep its own name (none overwrites
    another, whose events would be lost), and they list (``ls``) in the order they
    were moved aside, so the operator knows which is the latest."""
    frozen = time.gmtime(NOW)
    monkeypatch.setattr(time, "gmtime", lambda *_: frozen)
    path = tmp_path / "queue.db"
    contents = [f"damaged file {n}\n".encode() * 300 for n in range(3)]
    for content in contents:
        path.write_bytes(content)
        with QueueStore.open(path, limits=LIMITS) as fresh:
            assert fresh.stats().quarantined == str(moved_aside(path)[-1])
    moved = moved_aside(path)
    assert [file.read_bytes() for file in moved] == contents
    assert moved[0].name == f"queue.db.corrupt-{time.strftime('%Y%m%dT%H%M%SZ', frozen)}"


def test_the_fresh_queue_does_not_inherit_the_damage_report_of_the_file_moved_aside(
    tmp_path: Path,
) -> None:
    """A queue the running bridge found damaged is marked; at the restart it is moved
    aside and a fresh queue starts. If the mark stayed, ``status`` and the health
    check would go on calling the healthy fresh queue damaged (and every start would
    read it whole)."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    recovery.mark_damaged(path, "database disk image is malformed")  # the running bridge's
    break_schema(path)  # ... and opening it now fails with SQLITE_CORRUPT
    with QueueStore.open(path, limits=LIMITS) as fresh:
        (moved,) = moved_aside(path)
        stats = fresh.stats()
        assert stats.quarantined == str(moved)
        assert stats.damaged is None
    stats_now = read_stats(str(path))
    assert stats_now is not None and stats_now.damaged is None


def test_status_shows_what_the_check_found_wrong(tmp_path: Path) -> None:
    """The integrity check of a running bridge reports damage once and marks the file;
    ``status`` shows what was found, exactly, so the operator knows why a restart is
    asked for."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    null_an_event_id(path)
    problem = recovery.check_integrity(path, busy_timeout_s=1.0)
    assert problem == "quick_check: NULL value in events.event_id"
    stats = read_stats(str(path))
    assert stats is not None
    assert stats.damaged == problem
    assert stats.depth == 3  # the events that can still be read are still shown


def test_a_queue_that_cannot_be_opened_is_one_line_naming_it_and_the_cause(
    tmp_path: Path,
) -> None:
    """A queue file just made (empty) that another process holds locked: the bridge
    stops with one line naming the queue and why, not a bare "None"."""
    path = tmp_path / "queue.db"
    path.touch()
    holder = sqlite3.connect(path, isolation_level=None)
    try:
        holder.execute("PRAGMA locking_mode = EXCLUSIVE")
        holder.execute("BEGIN EXCLUSIVE")
        with pytest.raises(QueueError) as refused:
            QueueStore.open(path, limits=LIMITS, busy_timeout_s=0.05)
    finally:
        holder.close()
    message = str(refused.value)
    assert message.startswith(f"queue {path}: ")
    assert "locked" in message
    assert "\n" not in message


def test_a_queue_checked_whole_at_open_is_not_checked_again_at_the_first_upkeep(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A small queue is checked whole when the bridge opens it; reading it whole again
    at the first upkeep after every start doubles the I/O the check costs the robot
    (the next check is due a day later). A queue whose check at open ran out of time
    is finished at the first upkeep, which then finds damage the open did not reach."""
    checks: list[Path] = []
    real_check = recovery.check_integrity

    def counted(path: Path, busy_timeout_s: float) -> str | None:
        checks.append(path)
        return real_check(path, busy_timeout_s)

    monkeypatch.setattr("phytrace_edge.queue.store.check_integrity", counted)
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    with QueueStore.open(path, limits=LIMITS) as store:
        store.maintain()
    assert checks == []

    null_an_event_id(path)
    monkeypatch.setattr(recovery, "OPEN_CHECK_S", -1.0)  # no time at all: stopped at once
    monkeypatch.setattr(recovery, "PROGRESS_STEPS", 1)
    with QueueStore.open(path, limits=LIMITS) as store:
        assert store.stats().damaged is None  # the open did not get to the damage
        store.maintain()
        assert checks == [path]
        assert store.stats().damaged == "quick_check: NULL value in events.event_id"


@pytest.mark.parametrize("budget_s", [None, 60.0])
def test_a_check_that_cannot_read_the_file_says_so_not_that_it_ran_out_of_time(
    tmp_path: Path, budget_s: float | None
) -> None:
    """``quick_check`` answers None only for a check stopped at its time budget. A
    check that cannot read the file (another process holds it locked) must raise,
    with or without a budget: a None would be taken by the open for "the file is
    large, finish the check later" (opening a queue it could not check, and failing
    later with a less clear error than "locked by another process"), and by the
    maintenance check for its verdict, reporting "quick_check: None" as damage."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    holder = sqlite3.connect(path, isolation_level=None)
    checker = recovery.connect(path, busy_timeout_s=0.05)
    try:
        holder.execute("PRAGMA locking_mode = EXCLUSIVE")
        holder.execute("BEGIN EXCLUSIVE")
        with pytest.raises(sqlite3.OperationalError, match="locked"):
            recovery.quick_check(checker, budget_s)
    finally:
        checker.close()
        holder.close()
    checker = recovery.connect(path, busy_timeout_s=0.05)
    try:
        assert recovery.quick_check(checker, budget_s) == "ok"  # the same file, once free
    finally:
        checker.close()
