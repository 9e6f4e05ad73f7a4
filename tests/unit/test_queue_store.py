"""QueueStore on real SQLite files: put/claim/ack/release, leases, caps, TTL, codecs,
dead letters, corrupt files, disk full, busy locks, migrations, space reclaim."""

from __future__ import annotations

import contextlib
import io
import logging
import platform
import random
import sqlite3
import stat
import sys
import threading
import uuid
from pathlib import Path

import orjson
import pytest
import zstandard

from phytrace_edge.errors import QueueBusyError, QueueError
from phytrace_edge.queue.encoding.codecs import GZIP, NONE, ZSTD_DICT
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.records import DeadLetter, PutResult
from phytrace_edge.queue.storage import recovery
from phytrace_edge.queue.storage.migrate import migrate, migration_files
from phytrace_edge.queue.storage.recovery import connect
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.processes import wait_for
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event, seqs


@pytest.fixture
def clock() -> Clock:
    return Clock()


def test_file_is_private_wal_and_in_a_created_directory(open_store) -> None:
    store = open_store()
    store.put(event(1))
    assert store.path.parent.is_dir()
    assert stat.S_IMODE(store.path.stat().st_mode) == 0o600
    wal = Path(f"{store.path}-wal")
    assert wal.exists() and stat.S_IMODE(wal.stat().st_mode) == 0o600
    assert store._db.read("PRAGMA journal_mode")[0][0] == "wal"


def test_warns_when_the_volume_is_smaller_than_the_cap(
    open_store, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        open_store(limits=QueueLimits(max_bytes=2**60))
    assert "less than QUEUE_MAX_BYTES" in caplog.text
    assert "the volume is the cap" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        open_store("small.db", limits=QueueLimits(max_bytes=2 * MIB))
    assert "the volume is the cap" not in caplog.text


def test_put_claim_ack_round_trip_keeps_json_exact(open_store) -> None:
    store = open_store()
    events = [event(i, pad=i) for i in range(5)]
    assert put_events(store, events).accepted == 5
    batch = store.claim_batch(10, MIB)
    assert [orjson.loads(e.json) for e in batch.events] == events
    assert [e.event_id for e in batch.events] == [e["event_id"] for e in events]
    store.ack(batch)
    stats = store.stats()
    assert (stats.depth, stats.queued_total, stats.acked_total, stats.stored_bytes) == (0, 5, 5, 0)
    assert store.claim_batch(10, MIB) is None


def test_claims_are_oldest_first_and_never_overlap(open_store) -> None:
    store = open_store()
    put_events(store, [event(i) for i in range(10)])
    first = store.claim_batch(4, MIB)
    second = store.claim_batch(4, MIB)
    assert seqs(first) == [0, 1, 2, 3] and seqs(second) == [4, 5, 6, 7]
    store.release(first)
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2, 3]  # stops at the leased range
    assert seqs(store.claim_batch(10, MIB)) == [8, 9]


def test_batch_byte_bound_but_always_one_event(open_store) -> None:
    store = open_store()
    put_events(store, [event(0, pad=5000), event(1, pad=10), event(2, pad=10)])
    assert seqs(store.claim_batch(10, 100)) == [0]
    assert seqs(store.claim_batch(10, 200)) == [1]


def test_expired_lease_comes_back_to_another_sender(tmp_path: Path, clock: Clock) -> None:
    path = tmp_path / "q.db"
    limits = QueueLimits(max_bytes=64 * MIB)
    crashed = QueueStore.open(path, limits=limits, clock=clock, lease_s=30)
    put_events(crashed, [event(i) for i in range(3)])
    assert seqs(crashed.claim_batch(10, MIB)) == [0, 1, 2]
    other = QueueStore.open(path, limits=limits, clock=clock, lease_s=30)
    assert other.claim_batch(10, MIB) is None
    clock.now += 31
    assert seqs(other.claim_batch(10, MIB)) == [0, 1, 2]
    crashed.close()
    other.close()


def test_renew_keeps_the_lease(open_store, clock: Clock) -> None:
    store = open_store(lease_s=30)
    store.put(event(1))
    batch = store.claim_batch(1, MIB)
    clock.now += 20
    assert store.renew(batch)
    clock.now += 20
    assert store.claim_batch(1, MIB) is None
    clock.now += 11
    assert store.renew(batch) is False  # expired and cleaned up by a claim
    assert store.claim_batch(1, MIB) is not None


def test_event_cap_drop_oldest(open_store) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, max_events=5))
    put_events(store, [event(i) for i in range(5)])
    result = put_events(store, [event(i) for i in range(5, 8)])
    assert (result.accepted, result.dropped) == (3, 0)
    assert seqs(store.claim_batch(10, MIB)) == [3, 4, 5, 6, 7]
    assert store.stats().drops == {"cap_events": 3}


def test_event_cap_drop_newest(open_store) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, max_events=5, on_full="drop_newest"))
    put_events(store, [event(i) for i in range(4)])
    result = put_events(store, [event(i) for i in range(4, 8)])
    assert (result.accepted, result.dropped) == (1, 3)
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2, 3, 4]
    assert store.stats().drops == {"cap_events": 3}


def test_drop_oldest_spares_events_being_sent(open_store) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, max_events=4))
    put_events(store, [event(i) for i in range(4)])
    sending = store.claim_batch(2, MIB)
    put_events(store, [event(4), event(5)])
    assert seqs(store.claim_batch(10, MIB)) == [4, 5]
    store.ack(sending)
    assert store.stats().drops == {"cap_events": 2}


@pytest.mark.parametrize("policy", ["drop_oldest", "drop_newest"])
def test_byte_cap_bounds_the_file(open_store, policy: str) -> None:
    cap = 2 * MIB
    store = open_store(limits=QueueLimits(max_bytes=cap, on_full=policy), compression="none")
    for start in range(0, 3000, 100):
        result = put_events(store, [event(i, pad=2000) for i in range(start, start + 100)])
        assert store.file_bytes() <= cap + 64 * 1024  # the -shm index is not data
        if policy == "drop_oldest":
            assert result.dropped == 0  # room is made by dropping the oldest
    stats = store.stats()
    assert stats.drops["cap_bytes"] > 0
    assert stats.depth + stats.drops["cap_bytes"] == 3000
    first = seqs(store.claim_batch(1, MIB))[0]
    assert (first > 0) if policy == "drop_oldest" else (first == 0)


def test_ttl_expires_old_events_but_not_leased_ones(open_store, clock: Clock) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, ttl_s=3600), lease_s=7200)
    put_events(store, [event(i) for i in range(3)])
    sending = store.claim_batch(1, MIB)
    clock.now += 1800
    put_events(store, [event(3)])
    clock.now += 1801
    assert store.expire() == 2
    assert store.stats().drops == {"ttl": 2}
    rest = store.claim_batch(10, MIB)
    assert seqs(rest) == [3]
    store.ack(rest)
    store.ack(sending)
    assert store.stats().depth == 0


@pytest.mark.parametrize("first", ["none", "gzip", "zstd"])
@pytest.mark.parametrize("then", ["none", "gzip", "zstd"])
def test_rows_stay_readable_when_compression_changes(open_store, first: str, then: str) -> None:
    store = open_store(compression=first)
    put_events(store, [event(i, pad=300) for i in range(3)])
    codec = store._db.read("SELECT codec FROM events LIMIT 1")[0][0]
    assert codec == {"none": NONE, "gzip": GZIP, "zstd": ZSTD_DICT}[first]
    store.close()
    reopened = open_store(compression=then)
    reopened.put(event(3, pad=300))
    assert seqs(reopened.claim_batch(10, MIB)) == [0, 1, 2, 3]


def test_zstd_dictionary_shrinks_events_and_is_kept_in_the_database(open_store) -> None:
    from phytrace_edge import run_simulation

    events: list[dict] = []
    run_simulation(100, sink=events.append)
    store = open_store()
    put_events(store, events)
    stats = store.stats()
    json_bytes = sum(len(orjson.dumps(e)) for e in events)
    assert stats.stored_bytes * 5 < json_bytes  # at least 5x smaller at rest
    (dict_id,) = store._db.read("SELECT DISTINCT dict_id FROM events")[0]
    assert (
        store._db.read("SELECT count(*) FROM zstd_dictionaries WHERE dict_id = ?", (dict_id,))[0][0]
        == 1
    )


def test_rows_of_a_retired_dictionary_stay_readable(open_store) -> None:
    samples = [orjson.dumps(event(i, pad=i % 50)) for i in range(2000)]
    old = zstandard.train_dictionary(4096, samples)
    store = open_store()
    body = zstandard.ZstdCompressor(dict_data=old).compress(orjson.dumps(event(7)))
    with store._db.transaction() as cursor:
        cursor.execute(
            "INSERT INTO zstd_dictionaries VALUES (?, ?, 0)", (old.dict_id(), old.as_bytes())
        )
        (next_id,) = cursor.execute("SELECT value FROM counters WHERE name = 'next_id'").fetchone()
        cursor.execute(
            "INSERT INTO events(id, last_id, event_id, queued_at, codec, dict_id, json_size, body) "
            "VALUES (?, ?, 'e7', 0, ?, ?, 40, ?)",
            (next_id, next_id, ZSTD_DICT, old.dict_id(), body),
        )
        cursor.execute("UPDATE counters SET value = value + 1 WHERE name IN ('depth', 'next_id')")
    store.close()
    assert seqs(open_store().claim_batch(1, MIB)) == [7]


def test_dead_letters_list_export_requeue_purge(open_store, clock: Clock) -> None:
    store = open_store()
    put_events(store, [event(i) for i in range(4)])
    batch = store.claim_batch(4, MIB)
    poison = batch.events[2]
    store.ack(batch, [DeadLetter(poison.id, "rejected: 422", 422, '{"error": "bad field"}')])
    stats = store.stats()
    assert (stats.depth, stats.acked_total, stats.dead_letters) == (0, 3, 1)
    assert stats.drops == {"rejected": 1}

    box = store.dead_letters
    (info,) = box.list()
    assert (info.event_id, info.reason, info.status_code) == (poison.event_id, "rejected: 422", 422)
    out = io.BytesIO()
    assert box.export(out) == 1
    line = orjson.loads(out.getvalue())
    assert line["event"] == event(2) and line["dead_letter"]["response"] == '{"error": "bad field"}'

    assert box.requeue() == 1
    assert box.count() == 0 and store.stats().dead_letters == 0
    assert seqs(store.claim_batch(10, MIB)) == [2]
    again = store.claim_batch(10, MIB)
    assert again is None
    store.put(event(9))
    batch = store.claim_batch(10, MIB)
    store.ack(batch, [DeadLetter(batch.events[0].id, "rejected: 400", 400)])
    clock.now += 100
    assert box.purge(before=clock.now - 200) == 0
    assert store.stats().dead_letters == 1
    assert box.purge() == 1 and box.count() == 0 and store.stats().dead_letters == 0


def test_requeue_into_a_full_queue_moves_what_fits_and_keeps_the_rest(open_store) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, max_events=5))
    put_events(store, [event(i) for i in range(3)])
    batch = store.claim_batch(3, MIB)
    store.ack(batch, [DeadLetter(e.id, "rejected: 422", 422) for e in batch.events])
    put_events(store, [event(i) for i in range(10, 13)])

    assert store.dead_letters.requeue() == 2  # 3 queued + 2 = the cap of 5
    stats = store.stats()
    assert (stats.depth, stats.dead_letters) == (5, 1)
    assert "cap_events" not in stats.drops, "a requeue never drops queued events"
    assert seqs(store.claim_batch(10, MIB, important_first=False)) == [10, 11, 12, 0, 1]
    (left,) = store.dead_letters.list()
    assert left.event_id == str(uuid.UUID(int=2))


def test_corrupt_file_is_moved_aside_and_a_fresh_queue_starts(
    tmp_path: Path, open_store, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "state" / "queue.db"
    path.parent.mkdir()
    garbage = b"this is not a database" * 100
    path.write_bytes(garbage)
    with caplog.at_level(logging.ERROR):
        store = open_store()
    moved = list(path.parent.glob("queue.db.corrupt-*"))
    assert len(moved) == 1 and moved[0].read_bytes() == garbage
    assert store.stats().quarantined == str(moved[0])
    assert "moved to" in caplog.text and caplog.records[0].levelno == logging.ERROR
    store.put(event(1))
    assert seqs(store.claim_batch(1, MIB)) == [1]


def test_damaged_pages_fail_the_check_and_are_moved_aside(tmp_path: Path, open_store) -> None:
    store = open_store()
    put_events(store, [event(i, pad=3000) for i in range(200)])
    store.reclaim_space(force=True)
    store.close()
    path = tmp_path / "state" / "queue.db"
    data = bytearray(path.read_bytes())
    data[8192:40960] = b"\xff" * (40960 - 8192)  # trash pages 3..10
    path.write_bytes(bytes(data))
    fresh = open_store()
    assert fresh.stats().depth == 0
    assert len(list(path.parent.glob("queue.db.corrupt-*"))) == 1


def damage_pages(path: Path, first: int, last: int) -> None:
    """Overwrite pages first..last (1-based, 4 KiB) of a closed queue file."""
    data = bytearray(path.read_bytes())
    data[(first - 1) * 4096 : last * 4096] = b"\xff" * ((last - first + 1) * 4096)
    path.write_bytes(bytes(data))


def noise_events(count: int) -> list[dict]:
    """Events that do not compress, so that they fill many pages."""
    return [event(i) | {"noise": random.Random(i).randbytes(3000).hex()} for i in range(count)]


@pytest.fixture
def huge(monkeypatch: pytest.MonkeyPatch) -> None:
    """As if the file were too big to check at open: the check stops at once."""
    monkeypatch.setattr(recovery, "OPEN_CHECK_S", 0.0)
    monkeypatch.setattr(recovery, "PROGRESS_STEPS", 1)


def test_damage_the_open_meets_past_its_check_is_moved_aside_at_once(
    tmp_path: Path, open_store, huge: None
) -> None:
    store = open_store()
    put_events(store, noise_events(50))
    store.reclaim_space(force=True)
    store.close()
    path = tmp_path / "state" / "queue.db"
    damage_pages(path, 2, 12)  # the tables the open reads
    fresh = open_store()
    assert fresh.stats().depth == 0 and fresh.stats().damaged is None
    assert len(list(path.parent.glob("queue.db.corrupt-*"))) == 1


def test_damage_found_in_use_is_reported_then_moved_aside_at_the_next_open(
    tmp_path: Path, open_store, huge: None
) -> None:
    store = open_store()
    put_events(store, noise_events(200))
    store.reclaim_space(force=True)
    store.close()
    path = tmp_path / "state" / "queue.db"
    pages = path.stat().st_size // 4096
    damage_pages(path, pages - 20, pages - 2)  # events the open does not read
    damaged = open_store()
    assert damaged.stats().damaged is None
    damaged.next_check_at = 0.0  # the whole check is due
    with contextlib.suppress(QueueError):  # expiry may meet the damage before the check
        damaged.maintain()
    assert damaged.stats().damaged
    assert read_stats(str(path), 0.0).damaged == damaged.stats().damaged
    damaged.close()

    fresh = open_store()  # the marker asks for the whole check: moved aside
    assert fresh.stats().depth == 0 and fresh.stats().damaged is None
    assert len(list(path.parent.glob("queue.db.corrupt-*"))) == 1
    assert not recovery.damage_marker(path).exists()


# the sleeps of SQLite's busy handler (usleep or nanosleep) by machine
SLEEP_SYSCALLS = {"x86_64": {35, 230}, "aarch64": {101, 115}}


def sleeping_in_sqlite(thread_id: int) -> bool:
    """Whether the thread is in a sleep system call: once it has begun a statement,
    the only sleep in SQLite is the busy handler's, between tries for a lock."""
    numbers = SLEEP_SYSCALLS.get(platform.machine())
    if numbers is None or sys.platform != "linux":
        pytest.skip(f"the sleep system calls of {sys.platform} {platform.machine()} are not listed")
    call = Path(f"/proc/self/task/{thread_id}/syscall").read_text().split()[0]
    return call.isdigit() and int(call) in numbers


def test_locked_queue_waits_for_the_lock_then_gives_up(tmp_path: Path, clock: Clock) -> None:
    path = tmp_path / "q.db"
    store = QueueStore.open(path, limits=QueueLimits(max_bytes=64 * MIB), busy_timeout_s=0.3)
    slow = QueueStore.open(path, limits=QueueLimits(max_bytes=64 * MIB), busy_timeout_s=30)
    holder = connect(path, 1.0)
    holder.execute("BEGIN IMMEDIATE")
    with pytest.raises(QueueBusyError, match="locked by another process"):
        store.put(event(1))

    begun = threading.Event()
    slow._db.connection.set_trace_callback(
        lambda sql: begun.set() if sql == "BEGIN IMMEDIATE" else None
    )
    outcome: dict[str, object] = {}

    def put_slowly() -> None:
        outcome["thread"] = threading.get_native_id()
        try:
            outcome["result"] = slow.put(event(2))
        except QueueError as exc:
            outcome["error"] = exc

    waiter = threading.Thread(target=put_slowly, daemon=True)
    waiter.start()
    assert begun.wait(10), "the second store never began its transaction"

    def waiting_for_the_lock() -> bool:
        assert waiter.is_alive(), f"the put ended while the lock was held: {outcome}"
        return sleeping_in_sqlite(int(str(outcome["thread"])))

    wait_for(waiting_for_the_lock, 10, "the put to wait in SQLite's busy handler", every=0.005)
    holder.execute("COMMIT")  # released only now: the put was refused and is retrying
    waiter.join(10)
    assert not waiter.is_alive()
    assert "error" not in outcome, outcome
    assert outcome["result"] == PutResult(accepted=1, dropped=0)  # retried inside the busy timeout
    assert store._db.read("PRAGMA integrity_check")[0][0] == "ok"
    assert store.stats().depth == 1
    store.close()
    slow.close()
    holder.close()


def test_disk_full_is_survived_counted_and_recovers(open_store) -> None:
    store = open_store(
        limits=QueueLimits(max_bytes=64 * MIB, on_full="drop_newest"), compression="none"
    )
    put_events(store, [event(i, pad=1000) for i in range(20)])
    pages = store._db.read("PRAGMA page_count")[0][0]
    store._db.read(f"PRAGMA max_page_count = {pages}")  # the "disk" is now full
    result = put_events(store, [event(i, pad=4000) for i in range(20, 30)])
    assert (result.accepted, result.dropped) == (0, 10)
    assert store.stats().drops == {"disk_full": 10}
    assert store.stats().depth == 20
    store._db.read(f"PRAGMA max_page_count = {pages * 100}")  # space returns
    assert store.put(event(99)).accepted == 1
    assert store._db.read("PRAGMA integrity_check")[0][0] == "ok"


def test_disk_full_with_drop_oldest_evicts_to_keep_new_data(open_store) -> None:
    store = open_store(compression="none")
    put_events(store, [event(i, pad=3000) for i in range(40)])
    pages = store._db.read("PRAGMA page_count")[0][0]
    store._db.read(f"PRAGMA max_page_count = {pages}")
    assert store.put(event(100, pad=3000)).accepted == 1
    stats = store.stats()
    assert stats.drops["disk_full"] >= 1
    assert stats.depth == 41 - stats.drops["disk_full"]


def test_a_database_of_the_first_migration_is_upgraded(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    old = sqlite3.connect(path, isolation_level=None)
    old.execute("PRAGMA journal_mode = WAL")
    assert migrate(old, up_to=1) == 1
    old.execute(
        "INSERT INTO events(event_id, queued_at, codec, dict_id, json_size, body) "
        "VALUES ('e1', 1.0, 0, NULL, 9, ?)",
        (orjson.dumps({"seq": 1}),),
    )
    old.execute("UPDATE counters SET value = 2 WHERE name = 'next_id'")
    old.execute("UPDATE counters SET value = 1 WHERE name = 'depth'")
    assert (
        old.execute("SELECT count(*) FROM sqlite_master WHERE name = 'dead_letters'").fetchone()[0]
        == 0
    )
    old.close()
    store = QueueStore.open(path, limits=QueueLimits(max_bytes=64 * MIB))
    assert store._db.read("PRAGMA user_version")[0][0] == len(migration_files())
    batch = store.claim_batch(5, MIB)
    assert seqs(batch) == [1]
    store.ack(batch, [DeadLetter(batch.events[0].id, "rejected: 422", 422)])
    assert store.stats().dead_letters == 1
    store.close()


def test_a_drained_backlog_gives_its_space_back(open_store) -> None:
    store = open_store(compression="none")
    for start in range(0, 6000, 500):
        put_events(store, [event(i, pad=2000) for i in range(start, start + 500)])
    store.reclaim_space(force=True)
    peak = store.file_bytes()
    assert peak > 10 * MIB
    while (batch := store.claim_batch(500, 4 * MIB)) is not None:
        store.ack(batch)
    store.maintain()
    reserve = Path(f"{store.path}-reserve").stat().st_size  # kept for a full disk
    assert store.file_bytes() - reserve < (peak - reserve) / 20


def test_concurrent_put_and_claim_threads_lose_nothing(open_store) -> None:
    store = open_store()
    delivered: list[int] = []
    done = threading.Event()

    def produce() -> None:
        for start in range(0, 2000, 50):
            put_events(store, [event(i) for i in range(start, start + 50)])
        done.set()

    def consume() -> None:
        while not (done.is_set() and store.stats().depth == 0):
            batch = store.claim_batch(64, MIB)
            if batch is not None:
                delivered.extend(seqs(batch))
                store.ack(batch)

    threads = [threading.Thread(target=produce), threading.Thread(target=consume)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert sorted(delivered) == list(range(2000))


def test_stats_are_readable_from_another_connection_during_a_write(open_store) -> None:
    store = open_store()
    put_events(store, [event(i) for i in range(10)])
    reader = sqlite3.connect(f"file:{store.path}?mode=ro", uri=True)
    with store._db.transaction() as cursor:
        cursor.execute("DELETE FROM events")  # uncommitted
        depth = reader.execute("SELECT value FROM counters WHERE name = 'depth'").fetchone()[0]
    assert depth == 10
    reader.close()


def test_the_on_full_policy_is_read_once_into_its_type() -> None:
    from phytrace_edge.queue.defaults import OnFull

    assert QueueLimits(on_full="drop_newest").on_full is OnFull.DROP_NEWEST
    assert not QueueLimits(on_full="drop_newest").makes_room
    assert QueueLimits().makes_room and QueueLimits().on_full is OnFull.THIN
    with pytest.raises(ValueError, match="bogus"):
        QueueLimits(on_full="bogus")


def test_the_walk_over_unleased_rows(open_store, clock: Clock) -> None:
    """``leases.unleased``: every row outside live leases, chunk by chunk, oldest or
    newest first, from an id on, going on after rows the caller deleted."""
    from phytrace_edge.queue.outbound import leases
    from phytrace_edge.queue.storage.rows import delete_range

    store = open_store(frame_events=1)  # one row per event
    put_events(store, [event(i) for i in range(10)])
    claimed = store.claim_batch(3, 10**7)  # rows 1..3 leased
    assert claimed is not None and [e.id for e in claimed.events] == [1, 2, 3]
    now = clock()

    def walk(**kwargs: object) -> list[list[int]]:
        chunks = store._db.write(
            lambda cursor: list(leases.unleased(cursor, now, "id", 4, **kwargs))
        )
        return [[row[0] for row in chunk.rows] for chunk in chunks]

    assert walk() == [[4, 5, 6, 7], [8, 9, 10]]
    assert walk(newest_first=True) == [[10, 9, 8, 7], [6, 5, 4]]
    assert walk(from_id=6) == [[6, 7, 8, 9], [10]]
    assert walk(where="AND id % 2 = 0") == [[4, 6, 8, 10]]

    def delete_as_it_goes(cursor) -> list[int]:
        seen = []
        for chunk in leases.unleased(cursor, now, "id, last_id", 2):
            seen += [row[0] for row in chunk.rows]
            delete_range(cursor, chunk.low, chunk.rows[-1][1])
        return seen

    assert store._db.write(delete_as_it_goes) == [4, 5, 6, 7, 8, 9, 10]
    assert store.counter("depth") == 3  # the leased rows stay
