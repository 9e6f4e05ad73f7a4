"""The queue file removed, moved or replaced under an open store, on real files: the
state is named, and the open database is copied back to its path with every event,
never mixed with a stale WAL left beside it."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from phytrace_edge.queue.storage import file_watch
from phytrace_edge.queue.store import QueueStore
from tests.queue_events import put_events


@pytest.fixture
def store(tmp_path: Path) -> Iterator[QueueStore]:
    with QueueStore.open(tmp_path / "q" / "queue.db") as store:
        put_events(store, [{"event_id": f"e{n}", "n": n} for n in range(50)])
        yield store


def depth_on_disk(path: Path) -> int:
    connection = sqlite3.connect(path)
    try:
        return int(
            connection.execute("SELECT value FROM counters WHERE name = 'depth'").fetchone()[0]
        )
    finally:
        connection.close()


def test_an_untouched_file_is_ok(store: QueueStore) -> None:
    assert store.watch_file().state == file_watch.OK
    assert store.file_keeper.restored == 0


def test_a_deleted_file_is_copied_back_with_its_events_and_new_ones(store: QueueStore) -> None:
    store.path.unlink()
    assert file_watch.look(store.file_keeper._descriptor, store.path).state == file_watch.DELETED
    assert store.watch_file().state == file_watch.OK
    assert store.file_keeper.restored == 1
    put_events(store, [{"event_id": "after", "n": 50}])
    assert store.counter("depth") == 51
    assert depth_on_disk(store.path) == 51  # the file at the path is the one written to


def test_a_renamed_file_is_named_and_copied_back(store: QueueStore) -> None:
    moved = store.path.with_name("old.db")
    store.path.rename(moved)
    state = file_watch.look(store.file_keeper._descriptor, store.path)
    assert state.state == file_watch.MOVED and state.open_path == str(moved)
    assert f"moved to {moved}" in str(state.describe(store.path))
    store.watch_file()
    assert depth_on_disk(store.path) == 50 and moved.exists()  # the moved file is left


def test_a_file_put_in_its_place_is_moved_aside_not_deleted(store: QueueStore) -> None:
    intruder = store.path.with_name("other.db")
    intruder.write_bytes(b"someone else's file")
    intruder.replace(store.path)
    assert store.watch_file().state == file_watch.OK
    aside = list(store.path.parent.glob("queue.db.displaced-*"))
    assert len(aside) == 1 and aside[0].read_bytes() == b"someone else's file"
    assert depth_on_disk(store.path) == 50


def test_a_gone_folder_is_named_and_nothing_is_made_in_its_place(
    store: QueueStore, tmp_path: Path
) -> None:
    folder = store.path.parent
    folder.rename(tmp_path / "elsewhere")
    state = store.watch_file()
    assert state.state == file_watch.FOLDER_GONE
    assert str(tmp_path / "elsewhere" / "queue.db") in str(state.describe(store.path))
    assert not folder.exists()
    put_events(store, [{"event_id": "meanwhile", "n": 50}])  # still written, to the open file
    (tmp_path / "elsewhere").rename(folder)
    assert store.watch_file().state == file_watch.OK
    assert depth_on_disk(store.path) == 51
