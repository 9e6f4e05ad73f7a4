"""The queue writer on a real queue file whose writes fail for a while: events wait in
memory, in order, and are written when the queue works again; at a stop, what could
not be written is counted (``unwritable``); the ledger and the queue's counters add up
at every moment."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime import writer as writer_module
from phytrace_edge.runtime.health import accounting
from phytrace_edge.runtime.writer import QueueWriter
from phytrace_edge.udm.types import Built
from tests.processes import wait_for


class FailingStore:
    """A real store whose ``put_many`` raises while ``failing`` is set, as a queue on
    a volume that throws I/O errors does."""

    def __init__(self, store: QueueStore) -> None:
        self._store = store
        self.failing = threading.Event()
        self.attempts = 0

    def put_many(self, *args: Any, **kwargs: Any) -> Any:
        self.attempts += 1
        if self.failing.is_set():
            raise QueueError(f"queue {self._store.path}: disk I/O error")
        return self._store.put_many(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._store, name)


@pytest.fixture
def store(tmp_path: Path) -> Iterator[QueueStore]:
    with QueueStore.open(tmp_path / "queue.db") as store:
        yield store


@pytest.fixture(autouse=True)
def quick_retries(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(writer_module, "RETRY_S", 0.01)


def event(n: int) -> Built:
    return Built({"event_id": f"e{n:05d}", "event_type": "telemetry.periodic", "n": n}, False)


def balanced_now(writer: QueueWriter) -> dict[str, Any]:
    stats, ledger = writer.snapshot()
    a = accounting(stats.counters, ledger["in_memory"])
    assert a["balanced"], a
    assert ledger["built"] == ledger["written"] + ledger["in_memory"] + sum(
        ledger["dropped"].values()
    ), ledger
    return dict(a)


def run(writer: QueueWriter) -> threading.Thread:
    thread = threading.Thread(target=writer.run, args=(writer.stop, lambda: None), daemon=True)
    thread.start()
    return thread


def queued_ns(store: QueueStore) -> list[int]:
    batch = store.claim_batch(10_000, 1 << 30, important_first=False)
    assert batch is not None
    import orjson

    return [orjson.loads(e.json)["n"] for e in batch.events]


def test_events_wait_in_memory_while_writes_fail_and_go_in_order_after(
    store: QueueStore,
) -> None:
    failing = FailingStore(store)
    writer = QueueWriter(failing)  # type: ignore[arg-type]
    thread = run(writer)
    failing.failing.set()
    for n in range(300):
        writer.put(event(n))
    wait_for(lambda: failing.attempts >= 3, 10, "writes to fail a few times")
    figures = writer.figures()
    assert figures["writes_failing_s"] is not None and figures["write_attempts_failed"] >= 1
    assert "disk I/O error" in str(figures["last_write_error"])
    assert figures["backlog"] == 300
    assert balanced_now(writer)["in_memory"] == 300

    failing.failing.clear()
    wait_for(lambda: writer.backlog() == 0, 10, "the backlog to be written")
    assert writer.figures()["writes_failing_s"] is None
    assert balanced_now(writer) == {
        **balanced_now(writer),
        "built": 300,
        "queued": 300,
        "in_memory": 0,
        "dropped": {},
    }
    writer.request_stop(within_s=5)
    thread.join(10)
    assert queued_ns(store) == list(range(300))


def test_a_stop_while_writes_fail_counts_the_rest_as_unwritable(store: QueueStore) -> None:
    failing = FailingStore(store)
    writer = QueueWriter(failing)  # type: ignore[arg-type]
    for n in range(10):
        writer.put(event(n))
    thread = run(writer)
    wait_for(lambda: writer.backlog() == 0, 10, "the first events written")
    failing.failing.set()
    for n in range(10, 60):
        writer.put(event(n))
    wait_for(lambda: failing.attempts >= 3, 10, "writes to fail")
    writer.request_stop(within_s=0.2)
    thread.join(10)
    assert not thread.is_alive()
    assert writer.dropped == {"unwritable": 50}
    writer.put(event(99))  # after the stop: never written, counted all the same
    assert writer.dropped == {"unwritable": 51}
    a = balanced_now(writer)
    assert (a["built"], a["queued"], a["dropped"]) == (61, 10, {"unwritable": 51})


def test_a_full_hand_off_drops_the_newest_and_counts_them(
    store: QueueStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(writer_module, "HANDOFF_MAX_EVENTS", 20)
    writer = QueueWriter(store)  # not running: nothing is written
    for n in range(25):
        writer.put(event(n))
    assert writer.dropped == {"writer_backlog": 5}
    a = balanced_now(writer)
    assert (a["built"], a["in_memory"], a["dropped"]) == (25, 20, {"writer_backlog": 5})


def test_one_event_json_cannot_hold_costs_only_itself(store: QueueStore) -> None:
    writer = QueueWriter(store)
    thread = run(writer)
    writer.put(event(0))
    writer.put(Built({"event_id": "bad", "text": "\ud800"}, False))  # a lone surrogate
    writer.put(event(2))
    wait_for(lambda: writer.backlog() == 0, 10, "the group written")
    writer.request_stop(within_s=5)
    thread.join(10)
    a = balanced_now(writer)
    assert (a["built"], a["queued"], a["dropped"]) == (3, 2, {"unencodable": 1})
    assert queued_ns(store) == [0, 2]


def test_the_slowest_commit_of_the_last_minute_is_remembered() -> None:
    commits = writer_module._Commits()
    commits.record(0.5, now=0.0)
    commits.record(2.0, now=1.0)
    commits.record(0.1, now=2.0)
    assert commits.last_s == 0.1 and commits.slowest_s(now=3.0) == 2.0
    assert commits.slowest_s(now=62.0) == 0.1  # the 2 s commit is over a minute old
