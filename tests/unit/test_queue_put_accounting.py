"""What a put says it did with events JSON cannot hold (queue/appender.py): the
``PutResult`` adds up (accepted + dropped = put) with the unencodable ones counted
as dropped, beside the caps' drops, and the log names the event that was dropped."""

from __future__ import annotations

import logging

import pytest

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event


@pytest.fixture
def clock() -> Clock:
    return Clock()


def unencodable(n: int) -> dict:
    """An event JSON cannot hold: a lone surrogate, as a bad decode of a sensor's
    string leaves it."""
    return {**event(n), "text": "\ud800"}


def test_an_unencodable_event_is_reported_dropped_by_the_put(open_store) -> None:
    """The caller (the writer, an import) learns from ``PutResult`` how many of its
    events the queue did not keep; an unencodable event left out of ``dropped`` would
    be an event lost without anyone told."""
    store = open_store()
    result = put_events(store, [event(0), unencodable(1), event(2), unencodable(3)])
    assert (result.accepted, result.dropped) == (2, 2)
    stats = store.stats()
    assert stats.depth == 2 and stats.queued_total == 4
    assert stats.drops == {"unencodable": 2}


def test_unencodable_and_capped_events_are_both_reported_dropped(open_store) -> None:
    """With the event cap refusing some of a put and JSON refusing another, ``dropped``
    counts both: accepted + dropped is every event put, as the counters say."""
    limits = QueueLimits(max_bytes=64 * MIB, max_events=3, on_full="drop_newest")
    store = open_store(limits=limits)
    put_events(store, [event(0), event(1)])
    result = put_events(store, [event(2), unencodable(3), event(4), event(5)])
    assert (result.accepted, result.dropped) == (1, 3)
    stats = store.stats()
    assert stats.drops == {"cap_events": 2, "unencodable": 1}
    assert stats.queued_total == 6 == stats.depth + sum(stats.drops.values())


def test_the_log_names_the_event_json_cannot_hold(
    open_store, caplog: pytest.LogCaptureFixture
) -> None:
    """An operator finds the producer of a dropped event by its id and type in the
    log: without them the ERROR says only that something was dropped."""
    store = open_store()
    bad = {**unencodable(7), "event_type": "robot.state"}
    with caplog.at_level(logging.ERROR):
        put_events(store, [bad])
    [record] = [r for r in caplog.records if "unencodable" in r.getMessage()]
    assert record.levelno == logging.ERROR
    assert bad["event_id"] in record.getMessage()
    assert "of type robot.state" in record.getMessage()
