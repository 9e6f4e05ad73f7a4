"""``status`` on a queue whose path SQLite's URI syntax would misread
(``queue/peek.py``'s ``read_stats``), on real files: a folder named with '%', '?' or
'#' is read as it is, read-only, and nothing is ever created."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import event

LIMITS = QueueLimits(max_bytes=64 * MIB)


def files_under(folder: Path) -> set[Path]:
    return {Path(root) / name for root, _, names in os.walk(folder) for name in names}


@pytest.mark.parametrize("folder", ["100%", "data%41", "why?mode=rw", "a#b", "odd %3f?#"])
def test_status_reads_a_queue_whose_path_has_uri_characters(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, folder: str
) -> None:
    """A queue under a folder named with '%', '?' or '#' (a site name, a mount
    label): misquoted, ``status`` and the health check read another path (and fail,
    or report an empty queue) while the bridge runs on this one."""
    monkeypatch.chdir(tmp_path)  # anything made by a misread path would land here
    path = tmp_path / folder / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i) for i in range(3)])
    before = files_under(tmp_path)
    stats = read_stats(str(path))
    assert stats is not None
    assert stats.depth == 3
    assert stats.path == str(path)
    made = files_under(tmp_path) - before
    # read-only: nothing made but the shared-memory files any WAL reader needs, beside it
    assert made <= {Path(f"{path}-wal"), Path(f"{path}-shm")}


def test_status_of_a_missing_queue_creates_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``status`` before the bridge ever ran: it says there is no queue; creating an
    empty file there would give the bridge a file it did not make (not mode 0600)."""
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "100%" / "queue.db"
    path.parent.mkdir()
    assert read_stats(str(path)) is None
    assert files_under(tmp_path) == set()
