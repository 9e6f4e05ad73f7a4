"""An ack with dead letters (queue/outbound/claims.py ``delete_accepted``) on real queue
files: an event the queue no longer holds when the ack comes (its lease ran out and TTL
took it) is not dead-lettered again, and does not stop the rest from being kept; what a
dead letter keeps of PhyCloud's answer is bounded, and nothing when it said nothing."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import DeadLetter
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event


@pytest.fixture
def clock() -> Clock:
    return Clock()


def test_a_dead_letter_for_an_event_gone_does_not_stop_the_others(
    open_store: Callable[..., QueueStore], clock: Clock
) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, ttl_s=1000.0), lease_s=60.0)
    store.put(event(0))
    clock.now += 900
    put_events(store, [event(i) for i in range(1, 4)])
    batch = store.claim_batch(10, MIB, important_first=False)
    assert batch is not None and len(batch.events) == 4
    clock.now += 200  # the lease ran out; event 0 is past its TTL, the others are not
    assert store.expire() == 1
    first, *_, last = batch.events
    store.ack(batch, [DeadLetter(first.id, "rejected: bad", 422), DeadLetter(last.id, "bad", 422)])
    assert [info.event_id for info in store.dead_letters.list()] == [last.event_id]
    stats = store.stats()
    assert (stats.depth, stats.acked_total, stats.dead_letters) == (0, 2, 1)
    assert stats.drops == {"ttl": 1, "rejected": 1}
    assert stats.queued_total == stats.acked_total + stats.dead_letters + sum(
        count for reason, count in stats.drops.items() if reason != "rejected"
    )


def test_a_dead_letter_keeps_at_most_4096_characters_of_the_answer_or_none(
    open_store: Callable[..., QueueStore],
) -> None:
    store = open_store()
    put_events(store, [event(i) for i in range(2)])
    batch = store.claim_batch(10, MIB)
    assert batch is not None
    quiet, wordy = batch.events
    store.ack(
        batch,
        [
            DeadLetter(quiet.id, "rejected: HTTP 400", 400),
            DeadLetter(wordy.id, "r", 400, "x" * 5000),
        ],
    )
    responses = {info.event_id: info.response for info in store.dead_letters.list()}
    assert responses == {quiet.event_id: None, wordy.event_id: "x" * 4096}


def test_an_export_counts_as_exported_not_as_delivered(
    open_store: Callable[..., QueueStore],
) -> None:
    """A verified hand-carry file has the events: they leave the queue as exported."""
    store = open_store()
    put_events(store, [event(i) for i in range(3)])
    batch = store.claim_batch(10, MIB)
    assert batch is not None
    store.ack(batch, exported=True)
    stats = store.stats()
    assert (stats.depth, stats.exported_total, stats.acked_total) == (0, 3, 0)
