"""An incident's parts in the queue, on a real queue file: stored as their own class,
sent before the rest of a backlog whatever hour they were queued in, found by an index,
and never thinned or dropped while periodic events are left."""

from __future__ import annotations

from pathlib import Path

import pytest

from phytrace_edge.queue.options import OnFull, QueueLimits
from phytrace_edge.queue.records import INCIDENT_CLASS
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event

HOUR = 3600.0


def incident_part(n: int, pad: int = 0) -> dict:
    return {**event(n, pad), "event_type": "incident"}


@pytest.fixture
def clock() -> Clock:
    return Clock()


def open_store(path: Path, clock: Clock, **limits: object) -> QueueStore:
    return QueueStore.open(path, limits=QueueLimits(**limits), clock=clock)  # type: ignore[arg-type]


def claimed_seqs(store: QueueStore) -> list[int]:
    batch = store.claim_batch(10, MIB)
    assert batch is not None
    store.ack(batch)
    return [int(e.event_id.replace("-", ""), 16) for e in batch.events]


def test_an_incident_goes_before_the_whole_backlog(tmp_path: Path, clock: Clock) -> None:
    """Three hours of backlog, an alarm in its first hour, an incident in its third:
    the incident first, then the first hour's alarm, then oldest first."""
    with open_store(tmp_path / "q.db", clock, max_bytes=64 * MIB) as store:
        put_events(store, [event(n) for n in range(20)])
        put_events(store, [event(20)], important=True)
        clock.now += 2 * HOUR
        put_events(store, [event(n) for n in range(21, 40)])
        put_events(store, [incident_part(40), incident_part(41)], important=True)
        rows = store._db.read("SELECT important, COUNT(*) FROM events GROUP BY important")
        assert dict(rows) == {0: 39, 1: 1, INCIDENT_CLASS: 2}
        assert claimed_seqs(store) == [40, 41]
        assert claimed_seqs(store) == [20]
        assert claimed_seqs(store) == list(range(10))


def test_incident_parts_are_found_by_an_index(tmp_path: Path, clock: Clock) -> None:
    with open_store(tmp_path / "q.db", clock, max_bytes=64 * MIB) as store:
        plan = store._db.read(
            "EXPLAIN QUERY PLAN SELECT id FROM events WHERE important = 2 ORDER BY id"
        )
    assert any("events_incident" in str(row) for row in plan), plan


def test_a_full_queue_thins_and_drops_periodic_events_not_incidents(
    tmp_path: Path, clock: Clock
) -> None:
    with open_store(
        tmp_path / "q.db", clock, max_bytes=64 * MIB, max_events=60, on_full=OnFull.THIN
    ) as store:
        put_events(store, [incident_part(n, pad=2000) for n in range(10)])
        for start in range(10, 400, 10):
            clock.now += 60
            put_events(store, [event(n, pad=100) for n in range(start, start + 10)])
        kept = dict(store._db.read("SELECT important, SUM(count) FROM events GROUP BY important"))
        assert kept[INCIDENT_CLASS] == 10
        assert sum(kept.values()) <= 60
        assert sum(store.stats().drops.values()) > 0
