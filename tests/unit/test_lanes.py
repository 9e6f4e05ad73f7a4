"""The two lanes after an outage, against a scripted PhyCloud on a real queue file: the
first request after the link comes back carries the newest events, LIVE_SHARE of the
backlog's requests are the live lane's, and LIVE_SHARE=0 is strictly oldest first."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pytest

from phytrace_edge.errors import TransientSendError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.ship.lanes import Lanes
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.responses import Reply
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import FunctionTransport
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock
from tests.unit.test_sender import FakeCloud, send_one


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def store(tmp_path: Path, clock: Clock):
    with QueueStore.open(
        tmp_path / "q.db", limits=QueueLimits(max_bytes=64 * MIB), clock=clock
    ) as store:
        yield store


def put(store: QueueStore, first: int, count: int) -> None:
    put_events(store, [{"event_id": f"e{i:05d}", "seq": i} for i in range(first, first + count)])


class Outage(FakeCloud):
    """PhyCloud down for the first request; while it is, the robot queues 30 events."""

    def __init__(self, store: QueueStore, clock: Clock) -> None:
        super().__init__()
        self.store, self.clock, self.down = store, clock, True

    def __call__(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        if self.down:
            self.down = False
            self.clock.now += 5
            put(self.store, 1000, 30)
            self.requests.append(([], dict(headers)))
            raise TransientSendError("connection refused")
        return super().__call__(body, headers)


def sender(store: QueueStore, cloud, live_share: float) -> Sender:
    policy = SendPolicy(
        batch_size=10, backlog_batch_size=100, requests_in_flight=1, live_share=live_share
    )
    return Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None, clock=store.now)


def seqs_of(request) -> list[int]:
    return [event["seq"] for event in request[0]]


def test_the_first_request_after_an_outage_carries_the_newest_events(store, clock) -> None:
    put(store, 0, 500)
    cloud = Outage(store, clock)
    s = sender(store, cloud, live_share=0.2)
    send_one(s)  # a probe fails (the outage), then its retry gets through
    assert seqs_of(cloud.requests[1]) == list(range(10))
    send_one(s)
    assert seqs_of(cloud.requests[2]) == list(range(1000, 1030)), "then the present"
    send_one(s)
    assert seqs_of(cloud.requests[3]) == list(range(10, 110)), "then the backfill"
    assert s.stats.live_events_sent == 30 and s.stats.backfill_events_sent == 110
    assert s.stats.newest_delivered_at == clock.now


def test_live_share_zero_sends_strictly_oldest_first(store, clock) -> None:
    put(store, 0, 500)
    cloud = Outage(store, clock)
    s = sender(store, cloud, live_share=0.0)
    assert s.drain()
    sent = [seq for request in cloud.requests[1:] for seq in seqs_of(request)]
    assert sent == [*range(500), *range(1000, 1030)]
    assert s.stats.live_events_sent == 0


def test_the_live_lane_gets_its_share_of_a_backlog(store, clock) -> None:
    put(store, 0, 2000)
    clock.now += 10  # the bridge starts on a backlog: what it queues from now on is live
    cloud = FakeCloud()
    s = sender(store, cloud, live_share=0.25)
    s._lanes.succeeded()  # the link is known to be up
    for n in range(8):  # the robot keeps queueing 5 events per request
        put(store, 10_000 + 5 * n, 5)
        send_one(s)
    lanes = ["live" if seqs_of(r)[0] >= 10_000 else "backfill" for r in cloud.requests]
    assert lanes == ["backfill"] * 3 + ["live"] + ["backfill"] * 3 + ["live"]
    assert seqs_of(cloud.requests[3]) == list(range(10_000, 10_020))
    assert seqs_of(cloud.requests[7]) == list(range(10_020, 10_040))
    assert all(seqs_of(r) == sorted(seqs_of(r)) for r in cloud.requests)


def test_lanes_turns_follow_the_share_and_an_outage() -> None:
    lanes = Lanes(live_share=0.5, now=100.0)
    assert lanes.failing, "until a request gets through, nothing says the link is up"
    lanes.succeeded()
    assert [lanes.live_turn() for _ in range(4)] == [None, 100.0, None, 100.0]
    lanes.failed(200.0)
    assert lanes.failing
    lanes.succeeded()
    assert not lanes.failing
    assert lanes.live_turn() == 200.0, "the first turn after an outage is the live lane's"
    assert Lanes(live_share=0.0, now=0.0).live_turn() is None
