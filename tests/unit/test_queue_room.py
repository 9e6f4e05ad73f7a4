"""Making room on real queue files: a full queue gives up about what a put needs and no
more (queue/space/caps.py); on a full volume whose reserve is gone, new events may only
fill pages the file already has (queue/space/full_disk.py); a write that must happen on
a full disk gives up the reserve and goes through (queue/storage/database.py)."""

from __future__ import annotations

import base64
import random
import sqlite3

import pytest

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import DeadLetter
from phytrace_edge.queue.space import caps
from phytrace_edge.queue.space.volume import Volume
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event


@pytest.fixture
def clock() -> Clock:
    return Clock()


def noisy(n: int, size: int = 700) -> dict:
    """An event of about ``size * 4 / 3`` bytes of JSON that does not compress away."""
    noise = base64.b64encode(random.Random(n).randbytes(size)).decode()
    return {**event(n), "noise": noise}


def pages(store) -> int:
    return store._db.read("PRAGMA page_count")[0][0]


# ------------------------------------------------------------------ the caps


@pytest.mark.parametrize("policy", ["drop_oldest", "thin"])
def test_a_full_queue_gives_up_about_what_each_put_needs(
    open_store, clock: Clock, policy: str
) -> None:
    """Once the byte cap is reached, each put of 10 events costs about 10 events of
    history (whole pages and whole frames round it up), not the backlog: a queue that
    emptied itself to take a few events would lose the outage it exists to keep."""
    store = open_store(limits=QueueLimits(max_bytes=1 * MIB, on_full=policy), frame_events=20)
    n, full_depth = 0, 0
    for _ in range(300):
        before = store.stats()
        put_events(store, [noisy(i) for i in range(n, n + 10)])
        n += 10
        clock.now += 1.0
        after = store.stats()
        given_up = sum(after.drops.values()) - sum(before.drops.values())
        if given_up:
            full_depth = full_depth or before.depth
            assert given_up <= 30, f"a put of 10 cost {given_up} events of history"
            assert after.depth >= 0.9 * full_depth, "the queue stays full of history"
    assert full_depth, "the cap was reached"
    stats = store.stats()
    assert stats.depth + sum(stats.drops.values()) == n
    if policy == "thin":
        assert set(stats.drops) == {"thinned"}


# ------------------------------------------------------------------ a full volume


def full_volume(monkeypatch: pytest.MonkeyPatch, store) -> None:
    """The volume is full but for less than twice the reserve (which is gone): as
    others filled it, while the queue's own cap still has room."""
    reserve = store._db.reserve
    assert reserve.release(), "given up for a full disk"
    volume = Volume(free=2 * reserve.size - 1, size=64 * MIB)
    monkeypatch.setattr(caps, "look_at", lambda folder: volume)
    store._caps.volume.forget()  # look at it now


@pytest.mark.parametrize("policy", ["drop_newest", "drop_oldest"])
def test_on_a_full_volume_new_events_never_grow_the_file(
    open_store, monkeypatch: pytest.MonkeyPatch, policy: str
) -> None:
    """With the reserve gone and the volume full, new events may fill only the pages
    the file already has: pages it grew for them could be the last bytes the next ack
    needs, and then the queue could neither drain nor take events. The put that would
    grow it is refused (drop_newest) or makes room by evicting the oldest first."""
    limits = QueueLimits(max_bytes=64 * MIB, on_full=policy)
    store = open_store(limits=limits, compression="none", frame_events=1)
    put_events(store, [noisy(i, 1500) for i in range(30)])
    store.put(noisy(30, 15000))  # a large event PhyCloud took: its pages are free now
    store.ack(store.claim_live(1, MIB, since=0.0))
    assert 0 < store._db.read("PRAGMA freelist_count")[0][0] < 8
    full_volume(monkeypatch, store)
    size = pages(store)

    result = put_events(store, [noisy(i, 1500) for i in range(100, 110)])  # ~20 KB
    assert pages(store) == size, "the file did not grow"
    refused_or_evicted = {"drop_newest": (0, 10), "drop_oldest": (10, 0)}[policy]
    assert (result.accepted, result.dropped) == refused_or_evicted
    stats = store.stats()
    assert stats.drops == {"disk_full": 10} and stats.depth == 30
    assert stats.queued_total == stats.depth + stats.acked_total + sum(stats.drops.values())

    assert store.put(event(200)).accepted == 1, "an event the free pages hold is taken"
    assert pages(store) == size


# ------------------------------------------------------------------ a write on a full disk


def test_an_ack_on_a_full_disk_gives_up_the_reserve_and_goes_through(
    open_store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk is full and a reader (``status``, another process) keeps the WAL from
    being truncated, so the ack's only room is the reserve: giving it up must be
    followed by the ack, or PhyCloud's accepted events (and its rejects, kept aside
    as dead letters) would be sent again and again while the disk stays full."""
    store = open_store(compression="none", busy_timeout_s=0.0)
    put_events(store, [noisy(i) for i in range(20)])
    store.put(noisy(20, 30000))  # PhyCloud will reject this one: kept as a dead letter
    batch = store.claim_live(1, MIB, since=0.0)
    [rejected] = batch.events

    reader = sqlite3.connect(store.path, isolation_level=None)
    try:
        reader.execute("BEGIN")
        reader.execute("SELECT count(*) FROM events").fetchone()  # holds its snapshot
        full = pages(store)
        store._db.read(f"PRAGMA max_page_count = {full}")  # the "disk" is full
        page_size = store._db.page_size
        reserve = store._db.reserve
        release = reserve.release

        def release_to_the_disk() -> bool:
            """Giving the reserve back gives its bytes to the disk."""
            released = release()
            if released:
                store._db.read(f"PRAGMA max_page_count = {full + reserve.size // page_size}")
            return released

        monkeypatch.setattr(reserve, "release", release_to_the_disk)
        store.ack(batch, [DeadLetter(rejected.id, "schema", 422, "bad")])
    finally:
        reader.rollback()
        reader.close()
    assert not reserve.path.exists(), "the reserve was given up"
    stats = store.stats()
    assert stats.depth == 20 and stats.dead_letters == 1
    [letter] = store.dead_letters.list()
    assert letter.event_id == rejected.event_id


def test_on_a_full_volume_events_are_evicted_only_when_the_new_ones_then_fit(
    open_store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The reserve gone, the volume full, no free page in the file (drop_oldest): a put
    of 10 events evicts the oldest until the new ones fit, and they are kept. Before,
    it evicted 10 (half the room the WAL needs), was refused anyway, and lost 10 old
    and 10 new events for nothing. A put that even the whole queue could not make room
    for is refused without evicting anything."""
    limits = QueueLimits(max_bytes=64 * MIB, on_full="drop_oldest")
    store = open_store(limits=limits, compression="none", frame_events=1)
    put_events(store, [noisy(i, 1500) for i in range(30)])
    assert store._db.read("PRAGMA freelist_count")[0][0] == 0
    full_volume(monkeypatch, store)
    size = pages(store)

    result = put_events(store, [noisy(i, 1500) for i in range(100, 110)])
    assert (result.accepted, result.dropped) == (10, 0), "the new events are kept"
    assert pages(store) == size, "the file did not grow"
    stats = store.stats()
    evicted = stats.drops["disk_full"]
    assert 10 <= evicted <= 30 and set(stats.drops) == {"disk_full"}
    assert stats.depth == 30 - evicted + 10
    assert stats.queued_total == stats.depth + sum(stats.drops.values())

    kept = stats.depth
    huge = put_events(store, [noisy(i, 60_000) for i in range(200, 210)])  # ~800 KB
    assert (huge.accepted, huge.dropped) == (0, 10)
    after = store.stats()
    assert after.depth == kept, "nothing was evicted for events that could not fit"
    assert after.drops["disk_full"] == evicted + 10
