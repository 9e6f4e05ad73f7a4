"""The dead letters an operator works through (queue/outbound/dead_letters.py), more
of them than one page or one chunk holds: listing pages, exporting every one of them,
and purging exactly the ones asked for (real queue files)."""

from __future__ import annotations

import io
from collections.abc import Callable

import orjson
import pytest

from phytrace_edge.queue.records import DeadLetter
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event


@pytest.fixture
def clock() -> Clock:
    return Clock()


def dead_letters(store: QueueStore, count: int, first: int = 0) -> list[str]:
    """Put ``count`` events and have PhyCloud reject every one; their event ids."""
    put_events(store, [event(i) for i in range(first, first + count)])
    batch = store.claim_batch(count, 64 * MIB)
    assert batch is not None and len(batch.events) == count
    store.ack(batch, [DeadLetter(e.id, "rejected: bad", 422) for e in batch.events])
    return [e.event_id for e in batch.events]


def test_list_shows_a_page_of_100_oldest_first(open_store: Callable[..., QueueStore]) -> None:
    store = open_store()
    ids = dead_letters(store, 105)
    assert [info.event_id for info in store.dead_letters.list()] == ids[:100]
    assert [info.event_id for info in store.dead_letters.list(offset=100)] == ids[100:]


@pytest.mark.parametrize("chunk", [2, 500])
def test_export_writes_every_dead_letter_whatever_the_chunk(
    open_store: Callable[..., QueueStore], chunk: int
) -> None:
    store = open_store()
    ids = dead_letters(store, 5)
    seen = [info.event_id for info, _ in store.dead_letters.iter_events(chunk=chunk)]
    assert seen == ids
    out = io.BytesIO()
    assert store.dead_letters.export(out) == 5
    lines = [orjson.loads(line) for line in out.getvalue().splitlines()]
    assert [line["event"]["event_id"] for line in lines] == ids


def test_purge_deletes_only_the_ids_given(open_store: Callable[..., QueueStore]) -> None:
    store = open_store()
    dead_letters(store, 4)
    box = store.dead_letters
    first, second, *rest = box.list()
    assert box.purge([first.id, second.id]) == 2
    assert [info.id for info in box.list()] == [info.id for info in rest]
    assert box.count() == 2 and store.stats().dead_letters == 2


def test_purge_of_ids_older_than_a_time_needs_both(
    open_store: Callable[..., QueueStore], clock: Clock
) -> None:
    store = open_store()
    old = dead_letters(store, 2)
    clock.now += 1000
    new = dead_letters(store, 2, first=10)
    box = store.dead_letters
    by_event = {info.event_id: info.id for info in box.list()}
    chosen = [by_event[old[0]], by_event[new[0]]]
    # of the two chosen, only the one that died before the time goes
    assert box.purge(chosen, before=clock.now - 500) == 1
    assert [info.event_id for info in box.list()] == [old[1], *new]
    assert box.purge(before=clock.now - 500) == 1  # the other old one
    assert [info.event_id for info in box.list()] == new
