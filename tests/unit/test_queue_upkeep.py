"""The store's upkeep and its one-event put (queue/store.py), on real queue files: space
goes back to the disk only once a backlog has drained and the figure says how much,
the whole integrity check runs on the queue's file once it is due and then not for a
day, and ``put`` keeps the class it was given."""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from phytrace_edge.queue import store as store_module
from phytrace_edge.queue.store import INTEGRITY_EVERY_S, QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event, seqs


@pytest.fixture
def clock() -> Clock:
    return Clock()


def noise_events(count: int) -> list[dict]:
    """Events that do not compress, so that they fill many pages."""
    return [event(i) | {"noise": random.Random(i).randbytes(3000).hex()} for i in range(count)]


def free_pages(store: QueueStore) -> int:
    return int(store._db.read("PRAGMA freelist_count")[0][0])


def send(store: QueueStore, count: int) -> None:
    batch = store.claim_batch(count, 64 * MIB)
    assert batch is not None
    store.ack(batch)


def test_space_goes_back_once_a_backlog_drained_and_the_figure_is_what_went(
    open_store: Callable[..., QueueStore],
) -> None:
    store = open_store()
    put_events(store, noise_events(500))
    store.reclaim_space()  # the WAL is truncated: what is measured next is the database
    send(store, 80)  # a sixth sent: its pages are free for new events, not given back
    store.reclaim_space()
    assert free_pages(store) > 0, "a partly drained queue keeps its free pages"
    send(store, 420)  # drained: most of the file is free pages
    before = store.file_bytes()
    freed = store.reclaim_space()
    after = store.file_bytes()
    assert freed == before - after > 0
    assert free_pages(store) == 0
    assert store.reclaim_space() == 0  # nothing more to give back


def test_the_integrity_check_runs_on_the_queue_when_due_then_daily(
    open_store: Callable[..., QueueStore], monkeypatch: pytest.MonkeyPatch
) -> None:
    store = open_store()
    checked: list[tuple[Path, float]] = []
    monkeypatch.setattr(
        store_module, "check_integrity", lambda path, timeout: checked.append((path, timeout))
    )
    store.next_check_at = time.monotonic() + 3600.0
    store.maintain()
    assert checked == []  # not due
    store.next_check_at = 0.0
    store.maintain()
    assert checked == [(store.path, store.busy_timeout_s)]
    assert store.next_check_at >= time.monotonic() + INTEGRITY_EVERY_S - 60.0
    store.maintain()
    assert len(checked) == 1  # the next one is a day away


def test_a_store_on_a_test_clock_records_no_step(open_store: Callable[..., QueueStore]) -> None:
    assert open_store().record_clocks() == 0.0


def test_put_keeps_an_important_events_class(open_store: Callable[..., QueueStore]) -> None:
    store = open_store()
    put_events(store, [event(i) for i in range(3)])
    store.put(event(3), important=True)
    store.put(event(4))
    assert seqs(store.claim_batch(1, MIB)) == [3]  # the hour's important events go first
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2]  # then the oldest
    assert seqs(store.claim_batch(10, MIB)) == [4]
