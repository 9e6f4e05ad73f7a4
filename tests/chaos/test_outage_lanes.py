"""Chaos: a long outage with a cap that forces thinning, then the link comes back.

The bridge runs in this process (the simulated robot at 50 Hz, a real queue file capped
at 900 events, real HTTP); the stub is a separate process killed with SIGKILL for 40 s
of robot time and restarted on the same port and database. Then:

- the robot's present reaches PhyCloud in the first requests after the reconnection,
  ahead of the backlog (the live lane);
- every event the builder marked important (a transition, a new goal, an alarm raised
  or cleared) reaches it, however much periodic history was thinned;
- the periodic history covers the whole outage, no coarser than `status` reported;
- every event built is delivered or counted as thinned, and nothing else was dropped.
"""

from __future__ import annotations

import contextlib
import itertools
import sqlite3
import time

import httpx

from phytrace_edge.queue.peek import read_stats
from phytrace_edge.runtime.options import queue_path
from phytrace_edge.udm.event import parse_timestamp
from phytrace_edge.udm.types import Built
from tests.processes import wait_for

RATE_HZ = 50
OUTAGE_EVENTS = 2000  # 40 s of robot time


def stub_events(endpoint: str) -> list[dict]:
    """Every event the stub holds, in the order it received them."""
    events, after = [], 0
    while True:
        page = httpx.get(
            f"{endpoint}/events", params={"after": after, "limit": 10000}, timeout=30
        ).json()
        if not page["events"]:
            return events
        events += page["events"]
        after = page["next_after"]


def carries_a_change(event: dict) -> bool:
    """A transition or a new goal: what the builder must mark important."""
    operational, navigation = event.get("operational", {}), event.get("navigation", {})
    return bool(operational.get("transitions") or navigation.get("new_goals"))


def test_after_an_outage_the_present_comes_first_and_nothing_important_is_thinned(
    stub, bridge_in_process
) -> None:
    bridge = bridge_in_process(
        stub.endpoint, start=False, QUEUE_MAX_EVENTS="900", SAMPLE_RATE_HZ=str(RATE_HZ)
    )
    service, built, settings = bridge.service, bridge.built, bridge.settings
    important: set[str] = set()
    queue_event = service.writer.put

    def note_class(event: Built, wait: bool = False) -> None:  # the builder's own verdict
        if event.important:
            important.add(event.event["event_id"])
        queue_event(event, wait)

    service.writer.put = note_class  # type: ignore[method-assign]
    service.start()
    wait_for(lambda: stub.stats()["unique"] >= 20, 30, "the first events at the stub")
    stub.kill()
    killed_at, built_before = time.time(), len(built)
    wait_for(lambda: len(built) >= built_before + OUTAGE_EVENTS, 120, "a long outage")
    stats = read_stats(str(queue_path(settings)), time.time())
    assert stats is not None and stats.drops.get("thinned", 0) > 0, "the cap forced thinning"
    coarsest = max(
        1 if band["keeps"] == "all" else int(band["keeps"].split()[-1]) for band in stats.resolution
    )
    with contextlib.closing(sqlite3.connect(f"file:{stub.db}?mode=ro", uri=True)) as db:
        received_before = db.execute("SELECT count(*) FROM events").fetchone()[0]
    back_at = time.time()  # the link is back from the moment the stub listens
    stub.start()
    wait_for(lambda: service.store.counter("depth") < 50, 60, "the backlog to drain")
    bridge.stop()

    events = stub_events(stub.endpoint)
    after_restart = events[received_before:]
    first_live = next(
        i for i, e in enumerate(after_restart) if parse_timestamp(e["captured_at"]) >= back_at
    )
    assert first_live <= 100, "the present came ahead of the 40 s backlog"

    delivered = {e["event_id"] for e in events}
    assert {e["event_id"] for e in built if carries_a_change(e)} <= important
    assert important <= delivered, "an important event was thinned or lost"
    transitions = [
        t
        for e in sorted(events, key=lambda e: e["captured_at"])
        for t in e.get("operational", {}).get("transitions", [])
    ]
    assert len(transitions) >= 2
    for before, after in itertools.pairwise(transitions):
        assert after.get("from") == before["to"], "a transition is missing"

    def in_the_outage(e: dict) -> bool:
        return killed_at <= parse_timestamp(e["captured_at"]) <= back_at

    during = sorted(parse_timestamp(e["captured_at"]) for e in events if in_the_outage(e))
    first_built = min(parse_timestamp(e["captured_at"]) for e in built if in_the_outage(e))
    assert during[0] == first_built, "the history reaches back to the outage's start"
    largest_gap = max(b - a for a, b in itertools.pairwise(during))
    assert largest_gap <= 2 * coarsest / RATE_HZ + 0.5, "no coarser than status reported"

    final = read_stats(str(queue_path(settings)), time.time())
    assert final is not None and set(final.drops) == {"thinned"}, final and final.drops
    assert len(built) == len(delivered) + final.drops["thinned"] + final.depth
