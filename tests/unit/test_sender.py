"""The sender against fake transports: retries, Retry-After, splitting, dead letters,
auth refusals, stopping, flushing, throttling. Waits are recorded, not slept."""

from __future__ import annotations

import gzip
import logging
import random
import threading
import time
from collections.abc import Mapping
from pathlib import Path

import orjson
import pytest
import zstandard

from phytrace_edge.errors import (
    EndpointRefusedError,
    QueueBusyError,
    TransientSendError,
    UnexpectedAnswerError,
)
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.responses import Reply, parse_retry_after
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.stats import SendStats
from phytrace_edge.ship.throttle import Throttle
from phytrace_edge.ship.transport import FunctionTransport, HttpTransport
from phytrace_edge.units import MIB
from tests.processes import wait_for
from tests.queue_events import put_events
from tests.unit.queue_fixtures import NOW, Y2001, Machine, put_stamped


class FakeCloud:
    """A scripted PhyCloud: ``script`` answers first, then everything is accepted."""

    def __init__(self, *script: object, reject=lambda event: None) -> None:
        self.script = list(script)
        self.reject = reject  # event -> reason when the event is bad data
        self.requests: list[tuple[list[dict], dict]] = []
        self.stored: dict[str, dict] = {}

    def __call__(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        encoding = headers.get("Content-Encoding")
        raw = (
            gzip.decompress(body)
            if encoding == "gzip"
            else (zstandard.ZstdDecompressor().decompress(body) if encoding == "zstd" else body)
        )
        events = orjson.loads(raw)["events"]
        self.requests.append((events, dict(headers)))
        if self.script:
            answer = self.script.pop(0)
            if isinstance(answer, Exception):
                raise answer
            status, extra = answer if isinstance(answer, tuple) else (answer, {})
            return Reply(status, extra, b'{"error": "scripted"}')
        for index, event in enumerate(events):
            reason = self.reject(event)
            if reason:
                return Reply(400, {}, orjson.dumps({"error": reason, "index": index}))
        for event in events:
            self.stored[event["event_id"]] = event
        return Reply(
            200, {}, orjson.dumps({"accepted": len(events), "duplicates": 0, "rejected": []})
        )


@pytest.fixture
def store(tmp_path: Path):
    with QueueStore.open(tmp_path / "q.db", limits=QueueLimits(max_bytes=64 * MIB)) as store:
        yield store


def put(store: QueueStore, count: int, start: int = 0, **extra) -> list[str]:
    events = [{"event_id": f"e{i:05d}", "seq": i, **extra} for i in range(start, start + count)]
    put_events(store, events)
    return [e["event_id"] for e in events]


def sender(store, cloud, waits=None, rng=None, **policy) -> Sender:
    policy.setdefault("batch_size", 10)
    return Sender(
        store,
        FunctionTransport(cloud),
        SendPolicy(**policy),
        rng=rng,
        sleep=(waits.append if waits is not None else lambda s: None),
    )


def send_one(s: Sender) -> int:
    """One step of the sender's pipeline in this thread, to look between two requests:
    claim and encode the next batch, then post it; the events it held (0: none due)."""
    prepared = s.prepare_next()
    return 0 if prepared is None else s.post(prepared)


def run_in_thread(s: Sender, beat=lambda: None) -> threading.Thread:
    """``Sender.run`` as the service runs it; stopped by ``stop_thread``."""
    worker = threading.Thread(target=s.run, args=(s.stop, beat))
    worker.start()
    return worker


def stop_thread(s: Sender, worker: threading.Thread) -> None:
    s.stop.set()
    worker.join(timeout=10)
    assert not worker.is_alive(), "a stop ends the sender's loop"


def test_delivers_in_batches_in_order(store) -> None:
    ids = put(store, 25)
    cloud = FakeCloud()
    s = sender(store, cloud, backlog_batch_size=10, requests_in_flight=1)
    assert s.drain() is True
    assert [len(events) for events, _ in cloud.requests] == [10, 10, 5]
    assert [e["event_id"] for events, _ in cloud.requests for e in events] == ids
    assert (s.stats.events_sent, s.stats.batches_sent) == (25, 3)
    assert store.stats().acked_total == 25


def test_a_backlog_goes_in_bigger_requests_and_live_events_in_small_ones(store) -> None:
    ids = put(store, 1234)
    cloud = FakeCloud()
    s = sender(store, cloud, backlog_batch_size=500, requests_in_flight=1)
    send_one(s)  # nothing says the link is up yet: the first request is a probe
    assert s.drain() is True
    assert [len(events) for events, _ in cloud.requests] == [10, 500, 500, 224]
    assert [e["event_id"] for events, _ in cloud.requests for e in events] == ids
    put(store, 7, start=2000)  # less than a live batch waiting: a live request
    assert s.drain() is True
    assert len(cloud.requests[-1][0]) == 7


def test_a_body_over_batch_max_bytes_is_halved_before_it_is_sent(store) -> None:
    put(store, 40, note="x" * 2000)
    cloud = FakeCloud()
    s = sender(store, cloud, batch_max_bytes=30_000, http_compression="none")
    assert s.drain() is True
    assert max(len(orjson.dumps({"events": events})) for events, _ in cloud.requests) <= 30_000
    assert sum(len(events) for events, _ in cloud.requests) == 40
    assert store.stats().acked_total == 40


def test_the_next_request_goes_out_while_one_is_in_flight(store) -> None:
    put(store, 400)
    cloud = FakeCloud()
    both_on_the_wire = threading.Barrier(2, timeout=10)  # broken if only one is

    def meet_then_answer(body, headers):
        if 1 <= len(cloud.requests) < 3:  # after the first request, a probe, got through
            both_on_the_wire.wait()
        return cloud(body, headers)

    s = Sender(
        store,
        FunctionTransport(meet_then_answer),
        SendPolicy(batch_size=10, backlog_batch_size=100, requests_in_flight=2),
        sleep=lambda s: None,
    )
    assert s.drain() is True
    assert store.stats().acked_total == 400


def test_two_requests_in_flight_deliver_every_event_once(store) -> None:
    ids = put(store, 3000)
    cloud = FakeCloud()
    s = sender(store, cloud, backlog_batch_size=100, requests_in_flight=2)
    assert s.drain() is True
    delivered = [e["event_id"] for events, _ in cloud.requests for e in events]
    assert sorted(delivered) == ids and len(delivered) == len(set(delivered))
    assert store.stats().acked_total == 3000 and store.stats().leased == 0


@pytest.mark.parametrize("encoding", ["gzip", "zstd", "none"])
def test_headers_and_encodings(store, encoding: str) -> None:
    put(store, 3)
    cloud = FakeCloud()
    sender(store, cloud, http_compression=encoding).drain()
    ((events, headers),) = cloud.requests
    assert len(events) == 3
    assert headers.get("Content-Encoding") == (None if encoding == "none" else encoding)
    assert headers["Content-Type"] == "application/json"
    assert headers["User-Agent"].startswith("phytrace-edge/")
    assert len(headers["Idempotency-Key"]) == 64


def test_idempotency_key_is_stable_for_the_same_batch(store) -> None:
    put(store, 4)
    cloud = FakeCloud(503)
    assert sender(store, cloud).drain() is True
    put(store, 4, start=4)
    assert sender(store, cloud).drain() is True
    (tried, first), (retried, second), (other, third) = cloud.requests
    assert retried == tried and second["Idempotency-Key"] == first["Idempotency-Key"]
    assert other != tried and third["Idempotency-Key"] != first["Idempotency-Key"]


def test_retries_5xx_and_timeouts_with_growing_jittered_backoff(store) -> None:
    """Try n waits a draw of the sender's rng between RETRY_MIN_S and the bound
    min(RETRY_MAX_S, RETRY_MIN_S * 2 ** (n - 1)): seeded, the waits are known."""
    put(store, 5)
    waits: list[float] = []
    cloud = FakeCloud(500, 502, TransientSendError("timeout"), 503, 504, 408, 425, 429)
    s = sender(store, cloud, waits, rng=random.Random(7), retry_min_s=1, retry_max_s=8)
    assert s.drain() is True
    assert len(cloud.requests) == 9 and len(cloud.stored) == 5
    assert s.stats.retries == 8
    bounds = [1, 2, 4, 8, 8, 8, 8, 8]
    assert all(1 <= wait <= bound for wait, bound in zip(waits, bounds, strict=True))
    same_seed = random.Random(7)
    assert waits == [same_seed.uniform(1, bound) for bound in bounds]
    assert max(waits[:3]) < 4 < max(waits[3:])  # this seed's draws show the growth
    assert store.stats().drops == {}


def test_retry_after_seconds_and_http_date_are_honoured(store) -> None:
    put(store, 2)
    waits: list[float] = []
    cloud = FakeCloud(
        (503, {"retry-after": "7"}), (429, {"retry-after": "Wed, 21 Oct 2099 07:28:00 GMT"})
    )
    sender(store, cloud, waits, retry_max_s=2).drain()
    assert 7 <= waits[0] <= 7 * 1.2
    assert 3600 <= waits[1] <= 3600 * 1.2  # an HTTP-date far away is capped at an hour


@pytest.mark.parametrize(
    ("value", "seconds"),
    [
        ("120", 120.0),
        ("0", 0.0),
        ("-5", 0.0),
        ("soon", None),
        ("", None),
        (None, None),
        ("Thu, 01 Jan 1970 00:00:10 GMT", 0.0),
        ("1e9", 3600.0),
        ("nan", None),
    ],
)
def test_parse_retry_after(value, seconds) -> None:
    assert parse_retry_after(value, now=1000.0) == seconds


def test_poison_event_is_isolated_and_dead_lettered(store) -> None:
    put(store, 250)
    put(store, 1, start=250, poison=True)
    put(store, 249, start=251)
    cloud = FakeCloud(reject=lambda e: "bad field" if e.get("poison") else None)
    s = sender(store, cloud, batch_size=500)
    assert s.drain() is True
    assert len(cloud.stored) == 499 and "e00250" not in cloud.stored
    (letter,) = store.dead_letters.list()
    assert letter.event_id == "e00250" and letter.status_code == 400
    assert s.stats.dead_lettered == 1 and store.stats().drops == {"rejected": 1}
    assert len(cloud.requests) <= 4  # split at the blamed index: before, it, after


def test_without_an_index_the_batch_is_bisected(store) -> None:
    put(store, 64)
    bad = {"e00003", "e00040"}

    def reject(event):  # PhyCloud that does not say which event is bad
        return "bad" if event["event_id"] in bad else None

    cloud = FakeCloud(reject=reject)
    cloud_call = cloud.__call__

    def no_index(body, headers):
        reply = cloud_call(body, headers)
        return Reply(reply.status, {}, b"{}") if reply.status == 400 else reply

    s = Sender(store, FunctionTransport(no_index), SendPolicy(batch_size=64), sleep=lambda s: None)
    assert s.drain() is True
    assert set(cloud.stored) == {f"e{i:05d}" for i in range(64)} - bad
    assert {d.event_id for d in store.dead_letters.list()} == bad
    assert s.stats.batches_split > 2


def test_413_splits_until_it_fits(store) -> None:
    put(store, 40)
    put(store, 1, start=40, blob="x" * 50_000)

    def small_bodies_only(body, headers):
        if len(body) > 20_000:
            return Reply(413, {}, b'{"error": "too large"}')
        return cloud(body, headers)

    cloud = FakeCloud()
    s = Sender(
        store,
        FunctionTransport(small_bodies_only),
        SendPolicy(batch_size=100, http_compression="none"),
        sleep=lambda s: None,
    )
    assert s.drain() is True
    assert len(cloud.stored) == 40
    (letter,) = store.dead_letters.list()
    assert letter.event_id == "e00040" and letter.status_code == 413


def test_incident_parts_are_counted_as_phycloud_answers_for_them(store) -> None:
    """``status`` counts incident parts sent and refused: from the events' JSON, as the
    bridge writes it (event_id, then event_type)."""
    events = [
        {"event_id": f"e{i:05d}", "event_type": "incident" if i % 3 == 0 else "x", "seq": i}
        for i in range(12)
    ]  # incidents: 0, 3, 6, 9
    put_events(store, events)
    cloud = FakeCloud(reject=lambda event: "bad" if event["seq"] in (6, 7) else None)
    s = sender(store, cloud, batch_size=12)
    assert s.drain() is True
    assert (s.stats.incident_parts_sent, s.stats.incident_parts_dead_lettered) == (3, 1)
    assert s.stats.dead_lettered == 2


def test_per_event_rejections_in_a_2xx_are_dead_lettered(store) -> None:
    put(store, 3)

    def partial(body, headers):
        return Reply(
            200,
            {},
            orjson.dumps(
                {
                    "accepted": 2,
                    "duplicates": 0,
                    "rejected": [{"index": 1, "event_id": "e00001", "reason": "unknown robot"}],
                }
            ),
        )

    Sender(store, FunctionTransport(partial), SendPolicy(), sleep=lambda s: None).drain()
    (letter,) = store.dead_letters.list()
    assert letter.event_id == "e00001" and "unknown robot" in letter.reason


@pytest.mark.parametrize("status", [401, 403, 415, 404, 301])
def test_refusals_keep_the_data_and_back_off_long(
    store, status: int, caplog: pytest.LogCaptureFixture
) -> None:
    put(store, 5)
    waits: list[float] = []
    cloud = FakeCloud(status, status, status)
    with caplog.at_level(logging.ERROR):
        s = sender(store, cloud, waits, retry_max_s=45)
        assert s.drain() is True
    assert waits == [45, 45, 45]
    assert len(cloud.stored) == 5 and store.stats().drops == {}
    assert f"HTTP {status}" in caplog.text
    assert s.stats.auth_failures == (3 if status in (401, 403) else 0)


def test_stop_while_retrying_releases_the_batch(store) -> None:
    put(store, 5)
    stop = threading.Event()

    def down(body, headers):
        stop.set()  # asked to stop while PhyCloud is down
        return Reply(503, {}, b"")

    s = Sender(store, FunctionTransport(down), SendPolicy(), stop=stop, sleep=stop.wait)
    s.run(s.stop)
    assert store.stats().depth == 5 and store.stats().leased == 0


def test_partial_batch_waits_for_the_flush_interval(store) -> None:
    now = [1000.0]
    put(store, 3)
    cloud = FakeCloud()
    s = Sender(
        store,
        FunctionTransport(cloud),
        SendPolicy(batch_size=10, flush_interval_s=2),
        clock=lambda: now[0],
        sleep=lambda s: None,
    )
    queued_at = store.backlog()[1]
    assert queued_at is not None
    now[0] = queued_at + 1.0
    idle_rounds: list[None] = []  # a beat while idle: the sender looked and nothing was due
    worker = run_in_thread(s, lambda: idle_rounds.append(None))
    try:
        wait_for(lambda: len(idle_rounds) >= 2, 10, "the sender to look twice")
        assert cloud.requests == [], "a partial batch went before FLUSH_INTERVAL_S"
        now[0] = queued_at + 2.0
        wait_for(lambda: cloud.requests, 10, "the partial batch")
    finally:
        stop_thread(s, worker)
    assert [len(events) for events, _ in cloud.requests] == [3]


def test_send_stats_count_what_their_methods_say() -> None:
    stats = SendStats()
    stats.add_sent(3, 120, 200, at=10.0)
    stats.add_sent(2, 80, 202, at=11.0)
    stats.delivered("live", 2, newest_queued_at=9.0)
    stats.delivered("backfill", 3, newest_queued_at=5.0)
    stats.count_retry(EndpointRefusedError("HTTP 401: bad key", status=401), at=12.0)
    stats.count_retry(EndpointRefusedError("HTTP 415: encoding", status=415), at=13.0)
    stats.count_retry(UnexpectedAnswerError("a captive portal", status=200), at=14.0)
    stats.count_split()
    stats.add_dead_lettered(4)
    stats.incident_parts(sent=3, dead_lettered=1)
    stats.set_status(400)
    assert stats.count_queue_error(QueueBusyError("busy"), at=15.0) == 1
    assert stats.count_queue_error(QueueBusyError("still busy"), at=16.0) == 2
    assert stats.as_dict() == {
        "events_sent": 5,
        "batches_sent": 2,
        "bytes_sent": 200,
        "retries": 3,
        "batches_split": 1,
        "dead_lettered": 4,
        "auth_failures": 1,  # the 401; a 415 is a refusal, not of the key
        "unexpected_answers": 1,
        "last_success_at": 11.0,
        "last_error": "a captive portal",
        "last_error_class": "HTTP 200",
        "last_error_at": 14.0,
        "last_status": 400,
        "last_refusal": "HTTP 415: encoding",
        "last_refusal_at": 13.0,
        "live_events_sent": 2,
        "backfill_events_sent": 3,
        "incident_parts_sent": 3,
        "incident_parts_dead_lettered": 1,
        "newest_delivered_at": 9.0,
        "queue_errors": 2,
        "last_queue_error": "still busy",
        "last_queue_error_at": 16.0,
    }


def test_throttle_spreads_bytes_over_time() -> None:
    clock = [0.0]
    waits: list[float] = []

    def sleep(seconds: float) -> None:
        waits.append(seconds)
        clock[0] += seconds

    throttle = Throttle(1000, sleep, clock=lambda: clock[0])
    for _ in range(5):
        throttle.wait(500)
    assert clock[0] == pytest.approx(1.5)  # 2500 bytes at 1000 B/s with a 1 s burst
    assert Throttle(None, sleep).wait(10**9) == 0


def test_plain_http_to_a_remote_host_warns(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        HttpTransport("http://127.0.0.1:9/api/v1", Secret("k"), 1).close()
        assert caplog.text == ""
        HttpTransport("http://phycloud.example.com/api/v1", Secret("phk_live_secret"), 1).close()
    assert "plain http" in caplog.text and "phk_live_secret" not in caplog.text


def test_a_drain_deadline_cuts_short_a_batch_that_keeps_retrying(store) -> None:
    put(store, 5)

    def down(body, headers):
        return Reply(503, {}, b"")

    s = Sender(store, FunctionTransport(down), SendPolicy(retry_min_s=0.01, retry_max_s=0.05))
    started = time.monotonic()
    assert s.drain(deadline=started + 0.5) is False
    assert time.monotonic() - started < 5
    assert store.stats().depth == 5 and store.stats().leased == 0  # released, not lost
    assert s.stats.retries > 0


def test_an_idle_sender_still_says_it_is_alive(store) -> None:
    """Nothing to send (a quiet robot, every topic silent) is no stall: the sender beats
    while idle, or status and the systemd watchdog would take it for hung."""
    beats: list[float] = []
    cloud = FakeCloud()
    s = sender(store, cloud, flush_interval_s=0.05)
    worker = run_in_thread(s, lambda: beats.append(time.monotonic()))
    try:
        wait_for(lambda: len(beats) >= 3, 10, "the idle sender's beats")
    finally:
        stop_thread(s, worker)  # and the idle sender hears the stop
    assert cloud.requests == [], "nothing was queued: the beats are the idle loop's"


def test_a_batch_retrying_across_a_clock_step_is_sent_again_repaired(tmp_path: Path) -> None:
    """PhyCloud is down when the wall clock steps: the batch the sender holds was
    repaired in the queue meanwhile, so it gives it back and sends the repaired one."""
    machine = Machine(wall=Y2001)
    with QueueStore.open(
        tmp_path / "q.db",
        limits=QueueLimits(max_bytes=64 * MIB),
        clocks=machine,  # type: ignore[arg-type]
    ) as store:
        store.record_clocks()
        put_stamped(store, machine, range(5))

        def step_while_waiting(seconds: float) -> None:
            if machine.wall < NOW:
                machine.wall, machine.synchronized = NOW, True
                machine.run(1.0)
                store.record_clocks()

        cloud = FakeCloud(503)
        s = Sender(
            store, FunctionTransport(cloud), SendPolicy(batch_size=10), sleep=step_while_waiting
        )
        assert s.drain() is True
    delivered = list(cloud.stored.values())
    assert len(delivered) == 5
    assert all(e["captured_at"].startswith("2026-") for e in delivered)
    assert all(e["wall_clock"]["corrected_by_s"] > 0 for e in delivered)
    assert [e["captured_at"][:4] for e in cloud.requests[0][0]] == ["2001"] * 5  # the first try


# ------------------------------------------------------------------ answers that do not add up


def accounting(accepted: int, **extra) -> Reply:
    """A 200 answer: ``accepted``, no duplicates, none rejected, unless ``extra`` says."""
    document = {"accepted": accepted, "duplicates": 0, "rejected": [], **extra}
    return Reply(200, {}, orjson.dumps(document))


BAD_ANSWERS = {
    "none-accepted": lambda events: accounting(0),
    "one-short": lambda events: accounting(len(events) - 1),
    "one-too-many": lambda events: accounting(len(events) + 1),
    "rejected-without-event-id": lambda events: accounting(
        len(events) - 1, rejected=[{"index": 0, "reason": "bad"}]
    ),
    "one-based-index": lambda events: accounting(
        len(events) - 1,
        rejected=[{"index": 1, "event_id": events[0]["event_id"], "reason": "bad"}],
    ),
    "unknown-event-id": lambda events: accounting(
        len(events) - 1, rejected=[{"index": 0, "event_id": "nope", "reason": "bad"}]
    ),
    "rejected-twice": lambda events: accounting(
        len(events) - 2,
        rejected=[{"event_id": events[0]["event_id"]}, {"event_id": events[0]["event_id"]}],
    ),
}


@pytest.mark.parametrize("bad", BAD_ANSWERS.values(), ids=BAD_ANSWERS.keys())
def test_an_answer_that_does_not_account_for_the_batch_deletes_nothing(store, bad) -> None:
    put(store, 10)
    requests: list[int] = []
    stop = threading.Event()

    def wrong(body: bytes, headers: Mapping[str, str]) -> Reply:
        events = orjson.loads(gzip.decompress(body))["events"]
        requests.append(len(events))
        if len(requests) == 5:
            stop.set()
        return bad(events)

    s = Sender(
        store, FunctionTransport(wrong), SendPolicy(batch_size=10), stop=stop, sleep=lambda s: None
    )
    assert s.drain() is False
    assert requests == [10, 10, 10, 5, 5]  # three answers in a row, then halves
    assert store.stats().depth == 10 and store.stats().acked_total == 0
    assert store.dead_letters.list() == [] and store.stats().drops == {}
    assert store.stats().leased == 0  # released, sent again later
    assert s.stats.unexpected_answers == 5 and s.stats.events_sent == 0
    assert s.stats.last_error is not None and "kept the batch" in s.stats.last_error


def test_an_answer_that_does_not_add_up_is_logged_and_retried_with_backoff(
    store, caplog: pytest.LogCaptureFixture
) -> None:
    put(store, 10)
    waits: list[float] = []
    cloud = FakeCloud()

    def zero_twice(body: bytes, headers: Mapping[str, str]) -> Reply:
        reply = cloud(body, headers)
        return accounting(0) if len(cloud.requests) <= 2 else reply

    s = Sender(
        store,
        FunctionTransport(zero_twice),
        SendPolicy(batch_size=10, retry_min_s=0.5, retry_max_s=30),
        sleep=waits.append,
    )
    with caplog.at_level(logging.WARNING):
        assert s.drain() is True
    assert [len(events) for events, _ in cloud.requests] == [10, 10, 10]  # no halving yet
    assert len(waits) == 2 and all(0.5 <= w <= 30 for w in waits)
    assert store.stats().acked_total == 10 and store.dead_letters.list() == []
    assert (s.stats.unexpected_answers, s.stats.batches_split) == (2, 0)
    lines = [r.getMessage() for r in caplog.records if "accounts for" in r.getMessage()]
    assert len(lines) == 2
    assert lines[0].startswith(
        "PhyCloud's answer accounts for 0 of 10 events (accepted 0, duplicates 0, "
        "rejected 0) - kept the batch, retrying in "
    )


def test_halves_down_to_the_event_whose_answers_never_add_up_and_keeps_it(store) -> None:
    """PhyCloud that never counts e00003: its batch is halved until the events it does
    count get through; e00003, alone, is neither deleted nor dead-lettered, but retried
    every RETRY_MAX_S until PhyCloud's answer accounts for it."""
    put(store, 8)
    requests: list[list[str]] = []
    waits: list[float] = []
    fixed = threading.Event()
    stop = threading.Event()

    def miscounts(body: bytes, headers: Mapping[str, str]) -> Reply:
        ids = [e["event_id"] for e in orjson.loads(gzip.decompress(body))["events"]]
        requests.append(ids)
        forgotten = int("e00003" in ids and not fixed.is_set())
        return accounting(len(ids) - forgotten)

    def sleep(seconds: float) -> None:
        waits.append(seconds)
        if len(requests) >= 16:
            stop.set()

    policy = SendPolicy(batch_size=10, retry_min_s=0.5, retry_max_s=45)
    s = Sender(store, FunctionTransport(miscounts), policy, stop=stop, sleep=sleep)
    assert s.drain() is False
    sizes = [len(ids) for ids in requests]
    assert sizes == [8, 8, 8, 4, 4, 4, 2, 2, 2, 2, 1, 1, 1, 1, 1, 1]
    assert requests[6] == ["e00000", "e00001"] and requests[10] == ["e00002"]
    assert all(ids == ["e00003"] for ids in requests[11:])
    assert waits[-3:] == [45, 45, 45]  # e00003 alone, after 3 answers: RETRY_MAX_S
    assert store.stats().depth == 8 and store.stats().acked_total == 0
    assert store.dead_letters.list() == [] and store.stats().drops == {}
    assert s.stats.batches_split == 3
    assert s.stats.unexpected_answers == 3 + 3 + 3 + 5

    fixed.set()  # PhyCloud counts it now: everything goes, nothing is lost
    stop.clear()
    assert s.drain() is True
    assert store.stats().acked_total == 8 and store.dead_letters.list() == []


def test_rejections_are_dead_lettered_by_event_id_in_any_order(store) -> None:
    put(store, 4)

    def rejects_two(body: bytes, headers: Mapping[str, str]) -> Reply:
        rejected = [
            {"index": 3, "event_id": "e00003", "reason": "late"},
            {"index": 1, "event_id": "e00001", "reason": "unknown robot"},
        ]
        return accounting(2, rejected=rejected)

    s = Sender(store, FunctionTransport(rejects_two), SendPolicy(), sleep=lambda s: None)
    assert s.drain() is True
    letters = {letter.event_id: letter.reason for letter in store.dead_letters.list()}
    assert letters == {"e00001": "rejected: unknown robot", "e00003": "rejected: late"}
    assert store.stats().acked_total == 2 and s.stats.unexpected_answers == 0
