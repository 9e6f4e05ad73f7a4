"""Opening a queue file that cannot be used as it is (``queue/storage/recovery.py``), on
real files: a queue another process holds locked is waited for and refused, never
taken for a damaged one and moved aside; a folder that cannot be made is one line; a
damaged schema is moved aside like any damage; and the operator's log line says how to
recover the moved file."""

from __future__ import annotations

import errno
import logging
import os
import sqlite3
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueBusyError, QueueError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.storage import sqlite_errors
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import event, seqs

LIMITS = QueueLimits(max_bytes=64 * MIB)


def moved_aside(path: Path) -> list[Path]:
    return sorted(path.parent.glob(f"{path.name}.corrupt-*"))


def test_a_queue_locked_by_another_process_is_refused_not_moved_aside(tmp_path: Path) -> None:
    """A bridge started while another process holds the queue locked (a second
    bridge, a long ``sqlite3`` session) stops with one line saying so; taken for a
    damaged file, the queue and its events would be moved aside and a fresh one
    started."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    holder = sqlite3.connect(path, isolation_level=None)
    try:
        holder.execute("PRAGMA locking_mode = EXCLUSIVE")  # keeps every reader out
        holder.execute("BEGIN EXCLUSIVE")
        with pytest.raises(QueueBusyError) as refused:
            QueueStore.open(path, limits=LIMITS, busy_timeout_s=0.05)
        assert str(refused.value) == f"queue {path}: locked by another process"
        assert moved_aside(path) == []
    finally:
        holder.close()  # the lock goes with the connection
    with QueueStore.open(path, limits=LIMITS) as store:  # the same queue, its events kept
        assert store.stats().quarantined is None
        batch = store.claim_batch(10, MIB)
        assert batch is not None and seqs(batch) == [0, 1, 2]


def test_a_folder_that_cannot_be_made_is_one_line(tmp_path: Path) -> None:
    """QUEUE_PATH in a folder that is a symlink to a place gone (an unmounted drive):
    the bridge stops with one line naming the queue and the cause, not a traceback or
    a bare "None"."""
    (tmp_path / "data").symlink_to(tmp_path / "unmounted" / "data", target_is_directory=True)
    path = tmp_path / "data" / "queue.db"
    with pytest.raises(QueueError) as refused:
        QueueStore.open(path, limits=LIMITS)
    assert str(refused.value) == (
        f"queue {path}: cannot create its folder ({os.strerror(errno.EEXIST)}) - check QUEUE_PATH"
    )


def break_schema(path: Path) -> None:
    """Damage the queue's schema as a torn write of its first page could: the
    ``counters`` table's definition no longer parses."""
    db = sqlite3.connect(path)
    db.execute("PRAGMA writable_schema = ON")
    db.execute("UPDATE sqlite_master SET sql = 'CREATE TABLE counters(' WHERE name = 'counters'")
    db.commit()
    db.close()


def test_a_queue_with_a_damaged_schema_is_moved_aside_and_a_fresh_one_starts(
    tmp_path: Path,
) -> None:
    """SQLite calls a schema it cannot parse "malformed database schema" (its code:
    SQLITE_CORRUPT). Such a file must be moved aside like any damaged one; refused
    instead ("cannot read"), it bricks the bridge at every start until someone moves
    it by hand. (Python 3.10 has no ``sqlite_errorcode``: there the error's text
    decides, ``test_an_error_without_its_code_is_known_by_its_text``.)"""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    break_schema(path)
    damaged = path.read_bytes()
    with QueueStore.open(path, limits=LIMITS) as fresh:
        (moved,) = moved_aside(path)
        assert moved.read_bytes() == damaged  # kept as it was, for inspection
        assert fresh.stats().quarantined == str(moved)
        put_events(fresh, [event(7)])
        batch = fresh.claim_batch(10, MIB)
        assert batch is not None and seqs(batch) == [7]


def test_the_log_line_of_a_file_moved_aside_says_how_to_recover_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The operator's one ERROR line names the file, where it went, and the command
    that recovers what can be read from it, on the moved file: ``sqlite3 <moved>
    '.recover'``."""
    path = tmp_path / "queue.db"
    path.write_bytes(b"not a queue at all\n" * 300)
    with caplog.at_level(logging.ERROR), QueueStore.open(path, limits=LIMITS):
        (moved,) = moved_aside(path)
    (line,) = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert line.startswith(f"queue {path} is unreadable (file is not a database): ")
    assert f"moved to {moved} and started a fresh queue" in line
    assert line.endswith(f"(sqlite3 {moved} '.recover')")
    assert "\n" not in line


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("malformed database schema (counters) - incomplete input", sqlite_errors.SQLITE_CORRUPT),
        ("database disk image is malformed", sqlite_errors.SQLITE_CORRUPT),
        ("file is not a database", sqlite_errors.SQLITE_NOTADB),
        ("database is locked", sqlite_errors.SQLITE_BUSY),
        ("database table is locked", sqlite_errors.SQLITE_LOCKED),
        ("access permission denied", sqlite_errors.SQLITE_PERM),
        ("disk I/O error", sqlite_errors.SQLITE_IOERR),
    ],
)
def test_an_error_without_its_code_is_known_by_its_text(text: str, code: int) -> None:
    """Python 3.10's sqlite3 gives no ``sqlite_errorcode``, only the message: a damaged
    schema known only as "cannot read" there bricked the bridge at every start (the
    file was refused instead of moved aside). An error made without the attribute is
    what 3.10 raises."""
    exc = sqlite3.DatabaseError(text)
    assert getattr(exc, "sqlite_errorcode", None) is None
    assert sqlite_errors.sqlite_code(exc) == code
