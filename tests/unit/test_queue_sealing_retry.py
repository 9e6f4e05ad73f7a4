"""A put's sealing (packing what has waited into frames, queue/appender.py ``_seal``)
that fails is not the put's failure: the events are already committed, later puts go
on, and sealing is tried again once ``SEAL_AFTER_S`` has passed."""

from __future__ import annotations

import sqlite3
from typing import cast

import pytest

from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S
from phytrace_edge.udm.types import Built, UdmEvent
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event, seqs


@pytest.fixture
def clock() -> Clock:
    return Clock()


def frames(store) -> int:
    return store._db.read("SELECT count(*) FROM events WHERE count > 1")[0][0]


def test_a_seal_that_could_not_write_does_not_stop_later_puts(open_store, clock: Clock) -> None:
    """Sealing takes the write lock after the put committed; when another process (a
    ``drain``, a sqlite3 shell) holds it at that moment, the put is still durable and
    the next puts must still be taken. Were they to raise, the writer would count every
    later event as unwritable while the queue is fine."""
    store = open_store(frame_events=4, busy_timeout_s=0.0)  # a busy lock fails at once
    put_events(store, [event(i) for i in range(8)])
    clock.now += SEAL_AFTER_S + 1  # those have waited: the next put seals them

    holders: list[sqlite3.Connection] = []

    def lock_out() -> None:
        """Another process takes the write lock between the put's commit and its seal."""
        holder = sqlite3.connect(store.path, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        holders.append(holder)

    try:
        result = store.put_many([Built(cast(UdmEvent, event(8)), False)], after_commit=lock_out)
    finally:
        for holder in holders:
            holder.rollback()
            holder.close()
    assert (result.accepted, result.dropped) == (1, 0)
    assert holders, "the lock was taken before the seal"
    assert frames(store) == 0, "the seal could not write"

    clock.now += 1.0
    assert store.put(event(9)).accepted == 1, "the next put is taken"
    clock.now += SEAL_AFTER_S
    assert store.put(event(10)).accepted == 1
    assert frames(store) >= 2, "sealing was tried again and packed what waited"
    assert seqs(store.claim_batch(100, MIB, important_first=False)) == list(range(11))
