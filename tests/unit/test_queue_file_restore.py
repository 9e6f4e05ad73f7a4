"""A queue file copied back after it was deleted or moved under the running bridge
(``queue/storage/file_watch.py``), on real files: the log line says how many events
were kept, and the copy is not mixed with the moved file's WAL."""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

import pytest

from phytrace_edge.queue.store import QueueStore
from tests.queue_events import put_events


def test_the_copy_back_line_says_how_many_events_were_kept(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """After an ``rm queue.db`` under the running bridge, the operator's WARNING line
    says how many events the copy kept: "0 event(s) kept" would tell them the backlog
    was lost when it was not."""
    path = tmp_path / "q" / "queue.db"
    with QueueStore.open(path) as store:
        put_events(store, [{"event_id": f"e{n}", "n": n} for n in range(50)])
        path.unlink()
        with caplog.at_level(logging.WARNING):
            store.watch_file()
        assert store.counter("depth") == 50
    (line,) = [
        r.getMessage() for r in caplog.records if "copied the open queue back" in r.getMessage()
    ]
    assert line == (
        f"queue {path}: copied the open queue back to its path (50 event(s) kept); the "
        "bridge goes on with the copy"
    )


def test_a_moved_file_written_by_another_process_is_not_mixed_into_the_copy(
    tmp_path: Path,
) -> None:
    """A process that had the queue open (an operator's ``sqlite3`` shell) goes on
    writing after the file was moved and the bridge copied it back. Its writes go
    through the moved file's WAL, which the copy must not pick up: left beside the
    copy under the queue's name, that WAL would be applied to the bridge's queue."""
    path = tmp_path / "q" / "queue.db"
    with QueueStore.open(path) as store:
        put_events(store, [{"event_id": f"e{n}", "n": n} for n in range(50)])
        shell = sqlite3.connect(path, isolation_level=None)
        try:
            assert shell.execute("SELECT count(*) FROM events").fetchone() == (50,)
            path.rename(path.with_name("old.db"))
            store.watch_file()
            shell.execute("INSERT INTO meta(key, value) VALUES ('written_by', 'the shell')")
            put_events(store, [{"event_id": "after", "n": 50}])
            assert store.counter("depth") == 51
        finally:
            shell.close()
    queue = sqlite3.connect(path)
    try:
        assert queue.execute("SELECT count(*) FROM meta WHERE key = 'written_by'").fetchone() == (
            0,
        )
        assert queue.execute("SELECT count(*) FROM events").fetchone() == (51,)
    finally:
        queue.close()
