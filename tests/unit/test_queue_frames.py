"""Frames on a real queue file: old events are packed and shrink, fresh ones stay
single for live sending, and claims, acks, dead letters, caps, TTL and late acks work
on whole frames without losing or doubling an event."""

from __future__ import annotations

import sqlite3

import orjson
import pytest

from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S, event_id_of, split_frame
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import DeadLetter
from phytrace_edge.queue.storage.migrate import migrate
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event, seqs


@pytest.fixture
def clock() -> Clock:
    return Clock()


def rows(store) -> list[tuple[int, int, int]]:
    """(id, last_id, count) of every row."""
    return store._db.read("SELECT id, last_id, count FROM events ORDER BY id")


def fill(store, clock: Clock, first: int, count: int, pad: int = 300) -> None:
    """Put ``count`` events one at a time, a tenth of a second apart (a live robot)."""
    for n in range(first, first + count):
        store.put(event(n, pad))
        clock.now += 0.1


def test_old_events_are_sealed_into_frames_that_read_back_exactly(open_store, clock) -> None:
    store = open_store(frame_events=10)
    fill(store, clock, 0, 30)
    single_bytes = store.counter("stored_bytes")
    assert [count for _, _, count in rows(store)] == [1] * 30, "fresh events stay single"

    clock.now += SEAL_AFTER_S
    store.put(event(30, 300))  # the writer's group commit seals what has waited
    assert [count for _, _, count in rows(store)] == [10, 10, 10, 1]
    assert store.counter("stored_bytes") < single_bytes / 2
    stats = store.stats()
    assert (stats.depth, stats.queued_total) == (31, 31)

    batch = store.claim_batch(25, MIB)  # whole frames: two fit in 25
    assert seqs(batch) == list(range(20))
    assert [e.json for e in batch.events] == [orjson.dumps(event(n, 300)) for n in range(20)]
    assert [e.event_id for e in batch.events] == [event(n)["event_id"] for n in range(20)]
    assert len({e.id for e in batch.events}) == 20
    store.ack(batch)
    assert store.stats().depth == 11 and store.stats().acked_total == 20


def test_frames_of_one_event_turn_sealing_off(open_store, clock) -> None:
    store = open_store(frame_events=1)
    fill(store, clock, 0, 30)
    clock.now += SEAL_AFTER_S
    with store._db.transaction() as cursor:
        assert store._sealer.seal(cursor, clock.now) == 0, "nothing is packed"
    assert [count for _, _, count in rows(store)] == [1] * 30


def test_a_claim_always_takes_at_least_one_whole_frame(open_store, clock) -> None:
    store = open_store(frame_events=10)
    fill(store, clock, 0, 10)
    clock.now += SEAL_AFTER_S
    store.put(event(10))
    batch = store.claim_batch(3, MIB)
    assert seqs(batch) == list(range(10))


def test_a_dead_letter_inside_a_frame_is_kept_alone(open_store, clock) -> None:
    store = open_store(frame_events=5)
    fill(store, clock, 0, 5)
    clock.now += SEAL_AFTER_S
    store.put(event(5))
    batch = store.claim_batch(5, MIB)
    poison = batch.events[3]
    store.ack(batch, [DeadLetter(poison.id, "rejected: 422", 422)])
    stats = store.stats()
    assert (stats.depth, stats.acked_total, stats.dead_letters) == (1, 4, 1)
    (info,) = store.dead_letters.list()
    assert info.event_id == event(3)["event_id"]
    assert store.dead_letters.requeue() == 1
    assert seqs(store.claim_batch(10, MIB, important_first=False)) == [5, 3]


def test_a_late_ack_never_deletes_a_frame_sealed_after_its_lease_ran_out(open_store, clock) -> None:
    store = open_store(frame_events=5, lease_s=5.0)
    fill(store, clock, 0, 5)
    stale = store.claim_batch(2, MIB)  # a sender that then hangs past its lease
    assert seqs(stale) == [0, 1]
    clock.now += SEAL_AFTER_S
    store.put(event(5))
    assert rows(store)[0][2] == 5, "the expired claim's events were sealed with the rest"
    store.ack(stale)  # it comes back and acks what it sent
    assert store.stats().depth == 6, "events 2-4 are still queued"
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2, 3, 4, 5]  # 0-1 again: deduplicated


def test_caps_and_ttl_take_whole_frames_and_count_every_event(open_store, clock) -> None:
    store = open_store(
        frame_events=10,
        limits=QueueLimits(max_bytes=64 * MIB, max_events=25, on_full="drop_oldest", ttl_s=100),
    )
    fill(store, clock, 0, 20)
    clock.now += SEAL_AFTER_S
    store.put(event(20))  # seals two frames
    put_events(store, [event(n) for n in range(21, 26)])  # one over the event cap
    assert store.stats().drops == {"cap_events": 10}, "the oldest frame, all of it"
    assert seqs(store.claim_batch(100, MIB))[0] == 10

    clock.now += 100 - SEAL_AFTER_S - 1.05  # the newest event of the frame is not yet old
    store.release(store.claim_batch(100, MIB))
    assert store.expire() == 0
    clock.now += 1
    assert store.expire() == 10  # the frame, as its newest event passes the TTL
    assert store.stats().depth == 6


def test_frames_use_every_codec(open_store, clock) -> None:
    for compression in ("none", "gzip", "zstd"):
        store = open_store(f"{compression}.db", compression=compression, frame_events=4)
        fill(store, clock, 0, 8)
        clock.now += SEAL_AFTER_S
        store.put(event(8))
        assert [count for _, _, count in rows(store)] == [4, 4, 1]
        assert seqs(store.claim_batch(100, MIB)) == list(range(9))


def test_a_queue_from_before_frames_is_migrated_and_readable(tmp_path, open_store) -> None:
    path = tmp_path / "state" / "queue.db"
    path.parent.mkdir()
    old = sqlite3.connect(path, isolation_level=None)
    old.execute("PRAGMA journal_mode = WAL")
    assert migrate(old, up_to=3) == 3
    old.executemany(
        "INSERT INTO events(id, event_id, queued_at, codec, dict_id, json_size, body) "
        "VALUES (?, ?, 1.0, 0, NULL, 9, ?)",
        [(n, event(n)["event_id"], orjson.dumps(event(n))) for n in (1, 2)],
    )
    old.execute("UPDATE counters SET value = 3 WHERE name = 'next_id'")
    old.execute("UPDATE counters SET value = 2 WHERE name = 'depth'")
    old.close()
    store = open_store()
    assert rows(store) == [(1, 1, 1), (2, 2, 1)]
    assert seqs(store.claim_batch(10, MIB)) == [1, 2]


def test_event_ids_are_read_from_the_json() -> None:
    assert event_id_of(b'{"event_id":"0190-ab","x":1}') == "0190-ab"
    assert event_id_of(b'{"x":{"event_id":"inner"},"event_id":"outer"}') == "outer"
    assert event_id_of(b'{"x":1}') == ""
    with pytest.raises(ValueError, match="a frame of 3 events holds 2"):
        split_frame(b"{}\n{}", 3)
