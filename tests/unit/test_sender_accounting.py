"""The sender's accounting when PhyCloud refuses some events of a batch: every event
put ends up delivered or dead-lettered, once, whether the batch went whole, in halves
(a body over BATCH_MAX_BYTES) or in several requests; and the sender's figures add up
over the batches (a fake transport, as in test_sender.py; a real queue file)."""

from __future__ import annotations

import gzip
import random
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

import orjson
import pytest

from phytrace_edge.errors import QueueBusyError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.ship.options import MIN_LEASE_S, SendPolicy, claim_lease_s
from phytrace_edge.ship.responses import Reply
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import FunctionTransport
from phytrace_edge.units import MIB
from tests.queue_events import put_events


@pytest.fixture
def store(tmp_path: Path) -> Iterator[QueueStore]:
    with QueueStore.open(tmp_path / "q.db", limits=QueueLimits(max_bytes=64 * MIB)) as store:
        yield store


def events(count: int, poison: set[int], noise: int = 0) -> list[dict]:
    """Numbered events; ``poison`` ones PhyCloud refuses; ``noise`` hex characters that
    do not compress (random, seeded)."""
    return [
        {
            "event_id": f"e{i:05d}",
            "seq": i,
            "poison": i in poison,
            "noise": random.Random(i).randbytes(noise // 2).hex(),
        }
        for i in range(count)
    ]


class RefusingCloud:
    """PhyCloud that takes every event but the poisoned ones, which its 200 answer
    rejects one by one (by event_id and index)."""

    def __init__(self) -> None:
        self.requests: list[list[str]] = []
        self.stored: list[str] = []

    def __call__(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        sent = orjson.loads(gzip.decompress(body))["events"]
        self.requests.append([e["event_id"] for e in sent])
        rejected = [
            {"index": i, "event_id": e["event_id"], "reason": "poisoned"}
            for i, e in enumerate(sent)
            if e["poison"]
        ]
        self.stored += [e["event_id"] for e in sent if not e["poison"]]
        answer = {"accepted": len(sent) - len(rejected), "duplicates": 0, "rejected": rejected}
        return Reply(200, {}, orjson.dumps(answer))


def test_a_halved_batch_keeps_the_dead_letters_of_both_halves(store: QueueStore) -> None:
    """A compressed body over BATCH_MAX_BYTES goes in halves; PhyCloud refuses an event
    in each: both are dead letters, the rest is acked, nothing is left or lost."""
    put_events(store, events(10, poison={1, 7}, noise=5000))
    cloud = RefusingCloud()
    policy = SendPolicy(batch_size=10, batch_max_bytes=20_000, http_compression="gzip")
    s = Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None)
    assert s.drain() is True
    assert [len(ids) for ids in cloud.requests] == [5, 5]  # one batch, halved
    letters = store.dead_letters.list()
    assert {letter.event_id for letter in letters} == {"e00001", "e00007"}
    assert {(letter.status_code, letter.response) for letter in letters} == {(None, "poisoned")}
    stats = store.stats()
    assert (stats.depth, stats.acked_total, stats.dead_letters) == (0, 8, 2)
    assert stats.queued_total == stats.acked_total + stats.dead_letters + stats.depth
    assert stats.drops == {"rejected": 2}
    assert (s.stats.dead_lettered, s.stats.batches_split) == (2, 1)


def test_the_dead_letters_of_every_batch_are_counted(store: QueueStore) -> None:
    put_events(store, events(30, poison={3, 14, 25}))
    cloud = RefusingCloud()
    s = Sender(
        store,
        FunctionTransport(cloud),
        SendPolicy(batch_size=10, backlog_batch_size=10, requests_in_flight=1),
        sleep=lambda s: None,
    )
    assert s.drain() is True
    assert [len(ids) for ids in cloud.requests] == [10, 10, 10]
    assert s.stats.dead_lettered == 3  # one in each batch, added up
    assert s.stats.events_sent == 30  # every event PhyCloud answered for
    stats = store.stats()
    assert (stats.acked_total, stats.dead_letters, stats.depth) == (27, 3, 0)
    assert sorted(cloud.stored) == [f"e{i:05d}" for i in range(30) if i not in {3, 14, 25}]


@pytest.mark.parametrize(
    ("retry_max_s", "timeout_s", "lease_s"),
    [(300.0, 30.0, 660.0), (25.0, 10.0, 70.0), (5.0, 10.0, MIN_LEASE_S)],
)
def test_a_claim_outlasts_two_retry_waits_and_requests(
    retry_max_s: float, timeout_s: float, lease_s: float
) -> None:
    """A batch still being retried is never taken by a second sender: its lease is
    twice the longest wait plus a request, and never below MIN_LEASE_S."""
    assert claim_lease_s(SendPolicy(retry_max_s=retry_max_s), timeout_s) == lease_s


def test_the_figures_say_when_and_how_the_last_answer_came(store: QueueStore) -> None:
    """A success sets last_status and last_success_at (the store's clock); a retry
    last_error_at and its status; a refusal of bad data its status."""
    now = [5000.0]
    put_events(store, events(3, poison=set()))
    answers = iter([Reply(503, {}, b"")])

    def down_once(body: bytes, headers: Mapping[str, str]) -> Reply:
        return next(answers, None) or RefusingCloud()(body, headers)

    s = Sender(
        store,
        FunctionTransport(down_once),
        SendPolicy(),
        clock=lambda: now[0],
        sleep=lambda s: None,
    )
    assert s.drain() is True
    figures = s.stats.as_dict()
    assert (figures["last_error_at"], figures["last_error_class"]) == (5000.0, "HTTP 503")
    assert (figures["last_success_at"], figures["last_status"]) == (5000.0, 200)

    put_events(store, [{"event_id": "bad", "seq": 9, "poison": True}])

    def refuses(body: bytes, headers: Mapping[str, str]) -> Reply:
        return Reply(400, {}, orjson.dumps({"error": "bad field", "index": 0}))

    s.transport = FunctionTransport(refuses)
    assert s.drain() is True
    assert s.stats.last_status == 400 and s.stats.dead_lettered == 1
    (letter,) = store.dead_letters.list()
    assert (letter.event_id, letter.status_code) == ("bad", 400)
    assert letter.response is not None and "bad field" in letter.response  # PhyCloud's words


def test_drain_reports_its_progress_by_batch(store: QueueStore) -> None:
    put_events(store, events(25, poison=set()))
    progress: list[int] = []
    s = Sender(
        store,
        FunctionTransport(RefusingCloud()),
        SendPolicy(batch_size=10, backlog_batch_size=10, requests_in_flight=1),
        sleep=lambda s: None,
    )
    assert s.drain(progress=progress.append) is True
    assert progress == [10, 10, 5]


def test_a_lease_that_cannot_be_renewed_while_retrying_is_no_failure(
    store: QueueStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The queue busy (another process writing) when the sender renews its claim
    between two tries: the batch is still sent, and acked."""
    put_events(store, events(5, poison=set()))

    def busy(batch: object) -> bool:
        raise QueueBusyError("database is locked")

    monkeypatch.setattr(store, "renew", busy)
    answers = iter([Reply(503, {}, b""), Reply(503, {}, b"")])
    cloud = RefusingCloud()
    tries: list[int] = []

    def down_twice(body: bytes, headers: Mapping[str, str]) -> Reply:
        tries.append(len(tries))
        return next(answers, None) or cloud(body, headers)

    s = Sender(store, FunctionTransport(down_twice), SendPolicy(), sleep=lambda s: None)
    assert s.drain() is True
    assert len(tries) == 3 and s.stats.retries == 2
    assert len(cloud.stored) == 5 and store.stats().acked_total == 5


def test_a_drain_deadline_bounds_each_wait(store: QueueStore) -> None:
    """A wait before a retry never goes past the drain's deadline (the backoff asks for
    far more)."""
    put_events(store, events(2, poison=set()))
    waits: list[float] = []

    def sleep(seconds: float) -> None:
        waits.append(seconds)
        time.sleep(seconds)  # the wait itself, as the product spends it

    def down(body: bytes, headers: Mapping[str, str]) -> Reply:
        return Reply(503, {}, b"")

    policy = SendPolicy(retry_min_s=30.0, retry_max_s=60.0)
    s = Sender(store, FunctionTransport(down), policy, sleep=sleep)
    started = time.monotonic()
    assert s.drain(deadline=started + 0.3) is False
    assert waits and all(0.0 <= wait <= 0.3 for wait in waits)
    assert store.stats().depth == 2 and store.stats().leased == 0


@pytest.mark.parametrize(("count", "noise", "requests"), [(1, 8000, [1]), (2, 5000, [1, 1])])
def test_a_body_over_batch_max_bytes_is_halved_down_to_one_event_that_goes_alone(
    store: QueueStore, count: int, noise: int, requests: list[int]
) -> None:
    """One event larger than BATCH_MAX_BYTES cannot be halved: it is sent as it is
    (PhyCloud's 413 would dead-letter it); two are sent one by one."""
    put_events(store, events(count, poison=set(), noise=noise))  # ~noise/2 bytes gzipped
    cloud = RefusingCloud()
    policy = SendPolicy(batch_size=10, batch_max_bytes=3000, http_compression="gzip")
    s = Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None)
    assert s.drain() is True
    assert [len(ids) for ids in cloud.requests] == requests
    assert store.stats().acked_total == count


@pytest.mark.parametrize("important_first", [True, False])
def test_the_backfill_claims_as_backfill_important_first_says(
    store: QueueStore, important_first: bool
) -> None:
    put_events(store, events(3, poison=set()))
    put_events(store, [{"event_id": "alarm", "seq": 3, "poison": False}], important=True)
    cloud = RefusingCloud()
    policy = SendPolicy(batch_size=10, important_first=important_first)
    s = Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None)
    assert s.drain() is True
    if important_first:
        assert cloud.requests == [["alarm"], ["e00000", "e00001", "e00002"]]
    else:
        assert cloud.requests == [["e00000", "e00001", "e00002", "alarm"]]
