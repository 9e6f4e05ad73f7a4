"""A queue file whose damage the bounded check at open did not reach fails the first
open, is moved aside and a fresh queue started (queue/store.py ``open``); that fresh
queue is set up as asked, QUEUE_SYNC included."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from phytrace_edge.queue.storage import recovery
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event

SYNCHRONOUS = {"full": 2, "normal": 1}  # PRAGMA synchronous: 1 NORMAL, 2 FULL


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def huge(monkeypatch: pytest.MonkeyPatch) -> None:
    """As if the file were too big to check at open: the check stops at once."""
    monkeypatch.setattr(recovery, "OPEN_CHECK_S", 0.0)
    monkeypatch.setattr(recovery, "PROGRESS_STEPS", 1)


def damage_pages(path: Path, first: int, last: int) -> None:
    """Overwrite pages first..last (1-based, 4 KiB) of a closed queue file."""
    data = bytearray(path.read_bytes())
    data[(first - 1) * 4096 : last * 4096] = b"\xff" * ((last - first + 1) * 4096)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("sync", ["full", "normal"])
def test_the_queue_started_after_unseen_damage_keeps_the_sync_setting(
    tmp_path: Path, open_store, huge: None, sync: str
) -> None:
    """QUEUE_SYNC=full (the default) is what makes a put survive a power cut (each
    commit an fsync). The queue started in place of a damaged file must keep it: a
    robot whose queue was once damaged would otherwise lose its last events at every
    power cut from then on, with nothing said."""
    store = open_store(sync=sync)
    noise = [event(i) | {"noise": random.Random(i).randbytes(3000).hex()} for i in range(50)]
    put_events(store, noise)
    store.reclaim_space(force=True)
    store.close()
    path = tmp_path / "state" / "queue.db"
    damage_pages(path, 2, 12)  # the tables the open reads, past its check

    fresh = open_store(sync=sync)
    assert len(list(path.parent.glob("queue.db.corrupt-*"))) == 1, "moved aside"
    assert fresh.stats().depth == 0
    assert fresh._db.read("PRAGMA synchronous")[0][0] == SYNCHRONOUS[sync]
    fresh.put(event(1))
    assert fresh._db.read("PRAGMA synchronous")[0][0] == SYNCHRONOUS[sync]
