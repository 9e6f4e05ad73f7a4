"""How the sender forms and paces batches (ship/sender.py), against a fake PhyCloud on a
real queue file: how much JSON a claim takes for a compressed or a plain body, when a
batch is due, that only answers *in a row* that do not add up halve a batch, and that a
busy queue while claiming is waited out, counted, and not fatal."""

from __future__ import annotations

import gzip
from collections.abc import Iterator, Mapping
from pathlib import Path

import orjson
import pytest

from phytrace_edge.errors import QueueBusyError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.responses import Reply
from phytrace_edge.ship.sender import JSON_PER_WIRE_BYTE, QUEUE_RETRY_S, Sender
from phytrace_edge.ship.transport import FunctionTransport
from phytrace_edge.units import MIB
from tests.queue_events import put_events


@pytest.fixture
def store(tmp_path: Path) -> Iterator[QueueStore]:
    with QueueStore.open(tmp_path / "q.db", limits=QueueLimits(max_bytes=64 * MIB)) as store:
        yield store


def events(count: int, pad: int = 0) -> list[dict]:
    return [{"event_id": f"e{i:05d}", "seq": i, "pad": "x" * pad} for i in range(count)]


class Cloud:
    """PhyCloud that takes everything, and records the events of each request."""

    def __init__(self) -> None:
        self.requests: list[list[str]] = []

    def __call__(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        raw = gzip.decompress(body) if headers.get("Content-Encoding") == "gzip" else body
        ids = [e["event_id"] for e in orjson.loads(raw)["events"]]
        self.requests.append(ids)
        return Reply(200, {}, orjson.dumps({"accepted": len(ids), "rejected": []}))


@pytest.mark.parametrize(("compression", "sizes"), [("gzip", [10]), ("none", [2, 2, 2, 2, 2])])
def test_a_claim_takes_json_for_what_the_wire_will_carry(
    store: QueueStore, compression: str, sizes: list[int]
) -> None:
    """BATCH_MAX_BYTES bounds the body on the wire: a compressed body may hold
    JSON_PER_WIRE_BYTE times as much JSON, a plain one only as much."""
    put_events(store, events(10, pad=1000))  # ~1050 bytes of JSON each, compressible
    cloud = Cloud()
    policy = SendPolicy(batch_size=10, batch_max_bytes=3000, http_compression=compression)
    assert JSON_PER_WIRE_BYTE * 3000 > 10 * 1050
    s = Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None)
    assert s.drain() is True
    assert [len(ids) for ids in cloud.requests] == sizes


def test_a_full_batch_is_due_at_once(store: QueueStore) -> None:
    cloud = Cloud()
    policy = SendPolicy(batch_size=5, flush_interval_s=3600)
    s = Sender(store, FunctionTransport(cloud), policy, sleep=lambda s: None)
    put_events(store, events(4))
    assert s.due().now is False and s.prepare_next() is None  # partial: waits
    put_events(store, events(5)[4:])
    assert s.due().now is True
    prepared = s.prepare_next()
    assert prepared is not None and len(prepared.batch.events) == 5


def test_only_answers_in_a_row_that_do_not_add_up_halve_a_batch(store: QueueStore) -> None:
    """Two answers that do not add up, an outage, two more: never three in a row, so
    the batch is not halved. The latency figure times the answer that counted."""
    put_events(store, events(10))
    cloud = Cloud()
    wrong = Reply(200, {}, orjson.dumps({"accepted": 0, "rejected": []}))
    script = iter([wrong, wrong, Reply(503, {}, b""), wrong, wrong])
    requests: list[int] = []

    def answer(body: bytes, headers: Mapping[str, str]) -> Reply:
        requests.append(len(orjson.loads(gzip.decompress(body))["events"]))
        return next(script, None) or cloud(body, headers)

    s = Sender(store, FunctionTransport(answer), SendPolicy(batch_size=10), sleep=lambda s: None)
    assert s.drain() is True
    assert requests == [10] * 6 and s.stats.batches_split == 0
    assert store.stats().acked_total == 10
    assert s.stats.latency_count == 1
    assert 0.0 <= s.stats.latency_sum_s < 60.0


def test_a_busy_queue_while_claiming_is_waited_out_and_counted(
    store: QueueStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    put_events(store, events(3))
    claim = store.claim_batch
    busy = iter([True])

    def once_busy(*args: object, **kwargs: object):
        if next(busy, False):
            raise QueueBusyError("database is locked")
        return claim(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(store, "claim_batch", once_busy)
    waits: list[float] = []
    cloud = Cloud()
    s = Sender(store, FunctionTransport(cloud), SendPolicy(), sleep=waits.append)
    assert s.drain() is True
    assert waits == [QUEUE_RETRY_S]  # nothing on the wire: a pause before trying again
    assert (s.stats.queue_errors, s.stats.last_queue_error) == (1, "database is locked")
    assert [len(ids) for ids in cloud.requests] == [3]
