"""Thinning level by level on a real queue file (queue/space/thinning.py): periodic
events that stay single rows (important events come too often for frames to form) are
halved, every other single row, at every level down to 1 in 64 before anything is
dropped, also when an alarm follows every periodic event; and the bytes the queue
says it holds stay exact through the rewrites."""

from __future__ import annotations

import base64
import random

import orjson
import pytest

from phytrace_edge.queue.encoding.frames import decode_rows
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event

CAP = QueueLimits(max_bytes=MIB // 2, on_full="thin")


@pytest.fixture
def clock() -> Clock:
    return Clock()


def noisy(n: int, size: int) -> dict:
    """An event that does not compress away, like real telemetry."""
    return {**event(n), "noise": base64.b64encode(random.Random(n).randbytes(size)).decode()}


def queued_seqs(store) -> list[int]:
    """The seq of every event in the queue, oldest first, leased or not."""
    rows = store._db.read(
        "SELECT id, last_id, count, queued_at, event_id, codec, dict_id, body FROM events "
        "ORDER BY id"
    )
    return [orjson.loads(e.json)["seq"] for e in decode_rows(store.codecs, rows)]


def test_single_periodic_rows_are_thinned_level_by_level_down_to_1_in_64(
    open_store, clock: Clock
) -> None:
    """Two periodic samples, then a state change (important), every second for 700 s:
    no run of periodic rows is long enough to be sealed into a frame, so thinning must
    halve single rows, and rows that are single again after a halving, at each level.
    A user then keeps the start of the outage at 1 in 64 and every state change; had a
    level left single rows whole, the queue would run out of things to thin and cut
    the outage's start off instead."""
    store = open_store(limits=CAP)
    important: set[int] = set()
    for second in range(700):
        n = 3 * second
        put_events(
            store,
            [noisy(n, 300), noisy(n + 1, 300), noisy(n + 2, 20)],
            [False, False, True],
        )
        important.add(n + 2)
        clock.now += 1.0

    stats = store.stats()
    assert stats.drops.get("thinned", 0) > 0, "the cap was reached"
    assert set(stats.drops) == {"thinned"}, "nothing was dropped while it could be thinned"
    assert stats.depth + stats.drops["thinned"] == 2100
    seqs = queued_seqs(store)
    assert important <= set(seqs), "every state change is kept"
    periodic = [s for s in seqs if s not in important]
    # at 1 in 64 a periodic event is kept every 32 s (96 seqs): the first within two
    assert periodic[0] < 2 * 96, "the outage's first minute is still there"
    assert stats.resolution[0]["keeps"] == "1 in 64", "the oldest is thinned to the floor"
    assert stats.resolution[-1]["keeps"] == "all", "the recent past keeps every event"


def test_the_bytes_held_stay_exact_through_thinning(open_store, clock: Clock) -> None:
    """``status`` shows the bytes the queue holds (``held_bytes``, its fill against the
    cap): after thinning rewrote rows they are still the bytes of the rows there, and a
    drained queue holds none. A count that drifted would show a drained queue as full,
    or a full one as having room."""
    store = open_store(limits=CAP, frame_events=20)
    n = 0
    for _ in range(300):
        put_events(store, [noisy(n + i, 150) for i in range(10)])
        n += 10
        clock.now += 1.0
    stats = store.stats()
    assert stats.drops.get("thinned", 0) > 0, "rows were rewritten by thinning"
    [(body_bytes,)] = store._db.read("SELECT sum(length(body)) FROM events")
    assert stats.held_bytes == body_bytes

    while batch := store.claim_batch(500, 64 * MIB):
        store.ack(batch)
    drained = store.stats()
    assert drained.depth == 0 and drained.held_bytes == 0


def test_periodic_events_between_alarms_are_thinned_not_all_deleted(
    open_store, clock: Clock
) -> None:
    """A periodic event and then an alarm, every second for 700 s: each periodic event
    is a single row between two important ones, and every periodic id is even (the
    alarms' odd). Thinning must keep every other one at each level, spread over the
    outage, until the floor; a rule by id parity deleted every periodic event at the
    first level (801 of 801 "thinned", the whole history gone but the alarms)."""
    store = open_store(limits=CAP)
    for second in range(700):
        put_events(store, [noisy(2 * second, 300), noisy(2 * second + 1, 20)], [False, True])
        clock.now += 1.0
    stats = store.stats()
    assert stats.drops.get("thinned", 0) > 0, "the cap was reached"
    assert set(stats.drops) == {"thinned"}, "nothing was dropped while it could be thinned"
    seqs = queued_seqs(store)
    assert {2 * s + 1 for s in range(700)} <= set(seqs), "every alarm is kept"
    periodic = [s for s in seqs if s % 2 == 0]
    oldest_hundred_seconds = [s for s in periodic if s < 200]
    assert oldest_hundred_seconds, "the outage's start keeps some of its periodic events"
    assert stats.resolution[0]["keeps"] != "all" and stats.resolution[-1]["keeps"] == "all"
