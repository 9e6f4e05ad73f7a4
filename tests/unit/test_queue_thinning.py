"""Thinning on a real queue file: a full queue halves its oldest periodic history
before it drops anything, keeps every important event, spreads what it keeps over the
whole outage, counts what it removed as ``thinned``, and reports the resolution left."""

from __future__ import annotations

import base64
import itertools
import random

import orjson
import pytest

from phytrace_edge.cli.status import render_status
from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S, decode_rows, split_frame
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import QueuedEvent
from phytrace_edge.runtime.health import Thresholds, report
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event

HOUR = 3600.0
CAP = QueueLimits(max_bytes=1 * MIB, on_full="thin")


def noisy(n: int) -> dict:
    """An event of ~250 bytes that does not compress away, like real telemetry."""
    return {**event(n), "noise": base64.b64encode(random.Random(n).randbytes(150)).decode()}


@pytest.fixture
def clock() -> Clock:
    return Clock()


def outage(store, clock: Clock, hours: float, rate_hz: float, important_every: int) -> set[int]:
    """Queue ``hours`` of events at ``rate_hz``, one second per commit; every
    ``important_every``-th event is important. The important seqs."""
    important, n = set(), 0
    per_second = max(1, round(rate_hz))
    for _ in range(int(hours * HOUR)):
        flags = [(n + i) % important_every == 0 for i in range(per_second)]
        put_events(store, [noisy(n + i) for i in range(per_second)], flags)
        important.update(n + i for i, flag in enumerate(flags) if flag)
        n += per_second
        clock.now += 1.0
    return important


def queued(store) -> list[QueuedEvent]:
    """Every event in the queue, oldest first, leased or not."""
    rows = store._db.read(
        "SELECT id, last_id, count, queued_at, event_id, codec, dict_id, body FROM events "
        "ORDER BY id"
    )
    return decode_rows(store.codecs, rows)


def test_a_full_queue_thins_the_oldest_history_and_keeps_every_important_event(
    open_store, clock
) -> None:
    store = open_store(limits=CAP, frame_events=20)
    important = outage(store, clock, hours=0.75, rate_hz=2, important_every=97)
    stats = store.stats()
    put = 2 * int(0.75 * HOUR)
    assert stats.queued_total == put
    assert stats.drops.get("thinned", 0) > 0, "the cap was reached and history was thinned"
    assert "cap_bytes" not in stats.drops, "nothing was dropped while it could be thinned"
    assert stats.depth + stats.drops["thinned"] == put, "every event kept or counted"

    seqs = [orjson.loads(e.json)["seq"] for e in queued(store)]
    assert important <= set(seqs), "every important event is still there"
    assert seqs[0] < 2 * 60, "the history still reaches back to the outage's first minute"
    periodic = sorted(s for s in seqs if s not in important)
    first_half = [s for s in periodic if s < put // 2]
    second_half = [s for s in periodic if s >= put // 2]
    assert len(first_half) < len(second_half), "the oldest history is the thinnest"
    assert max(b - a for a, b in itertools.pairwise(periodic)) <= 2**6 * 2 + 97


def test_a_thinned_frame_keeps_the_time_of_its_newest_event(open_store, clock) -> None:
    """A frame expires with its newest event (``newest_at``, the TTL's clock): after
    thinning at several levels each frame's ``newest_at`` is still exactly when its
    newest event was queued (two events a second here, event 0 the first)."""
    store = open_store(limits=CAP, frame_events=20)
    outage(store, clock, hours=0.75, rate_hz=2, important_every=10**9)
    [(start,)] = store._db.read("SELECT queued_at FROM events WHERE important = 1")
    frames = store._db.read(
        "SELECT count, queued_at, newest_at, codec, dict_id, body, thin_level FROM events "
        "WHERE count > 1"
    )
    assert {level for *_, level in frames} > {0}, "frames were thinned, some more than once"
    for count, queued_at, newest_at, codec, dict_id, body, _ in frames:
        events = split_frame(store.codecs.decode(codec, dict_id, body), count)
        first, last = (orjson.loads(events[i])["seq"] for i in (0, -1))
        assert newest_at == start + last // 2
        assert queued_at <= start + first // 2, "never younger than its first event"


def test_status_reports_the_resolution_left_by_age(open_store, clock) -> None:
    store = open_store(limits=CAP, frame_events=20)
    outage(store, clock, hours=0.75, rate_hz=2, important_every=10**9)
    bands = store.stats().resolution
    assert bands[0]["keeps"] != "all", "the oldest band is thinned"
    assert bands[-1]["keeps"] == "all", "the newest keeps every event"
    ages = [band["oldest_age_s"] for band in bands]
    assert ages == sorted(ages, reverse=True), "bands go from the oldest to the newest"
    important = 1  # event 0
    assert sum(band["events"] for band in bands) + important == store.stats().depth
    document = report(store.stats(), Thresholds(10.0, 300.0, 0.8, CAP.max_bytes), clock.now)
    history = next(line for line in render_status(document).splitlines() if "history" in line)
    assert history.endswith(": all") and f": {bands[0]['keeps']}," in history, history
    assert document["lanes"]["backlog_oldest_age_s"] == bands[0]["oldest_age_s"]


def test_drop_oldest_cuts_the_history_off_instead(open_store, clock) -> None:
    store = open_store(limits=QueueLimits(max_bytes=1 * MIB, on_full="drop_oldest"))
    outage(store, clock, hours=0.75, rate_hz=2, important_every=97)
    stats = store.stats()
    seqs = [orjson.loads(e.json)["seq"] for e in queued(store)]
    assert stats.drops.get("cap_bytes", 0) > 0 and "thinned" not in stats.drops
    assert seqs[0] > 2 * 60, "the start of the outage is gone"


def test_fresh_events_and_leased_ones_are_never_thinned(open_store, clock) -> None:
    store = open_store(limits=CAP, frame_events=20, lease_s=10 * HOUR)
    outage(store, clock, hours=0.25, rate_hz=2, important_every=10**9)
    held = store.claim_batch(200, 64 * MIB, important_first=False)
    held_seqs = [orjson.loads(e.json)["seq"] for e in held.events]
    outage(store, clock, hours=0.5, rate_hz=2, important_every=10**9)
    assert store.stats().drops.get("thinned", 0) > 0
    still = [orjson.loads(e.json)["seq"] for e in queued(store)]
    assert set(held_seqs) <= set(still), "events being sent are left alone"
    newest = store._db.read(
        "SELECT count(*) FROM events WHERE queued_at >= ? AND thin_level > 0",
        (clock.now - SEAL_AFTER_S,),
    )[0][0]
    assert newest == 0, "the live end keeps every event"
