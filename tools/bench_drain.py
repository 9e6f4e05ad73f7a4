"""Drain benchmark: ship a 100k-event backlog from the queue to the stub on loopback.

    .venv/bin/python tools/bench_drain.py                 # about 2 minutes
    .venv/bin/python tools/bench_drain.py --events 20000  # quick

For each Content-Encoding, side by side against the same stub process (fresh database
each run): phytrace-edge's sender draining the real queue (claim, decompress, build the
body, compress, POST, ack), and a baseline that POSTs the same batches, pre-encoded in
memory, with one httpx client and no queue at all: the ceiling of this transport. The
ratio says what the queue and the sender cost on top of HTTP. Events are simulated UDM
events (~3.7 KB of JSON), 500 per request.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx
import orjson

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from phytrace_edge import run_simulation
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.request import BodyEncoder, request_headers
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport
from phytrace_edge.units import GIB, MIB
from tests.processes import StubProcess

BATCH = 500


def sample_events(count: int) -> list[dict]:
    base: list[dict] = []
    run_simulation(600, sink=base.append, seed=11)
    return [{**base[i % len(base)], "event_id": str(uuid.uuid4())} for i in range(count)]


def run_ours(
    workdir: Path, stub: StubProcess, events: list[dict], encoding: str
) -> tuple[float, int]:
    store = QueueStore.open(
        workdir / f"queue-{encoding}.db", limits=QueueLimits(max_bytes=8 * GIB), sync="normal"
    )
    for start in range(0, len(events), 1000):
        store.put_many(events[start : start + 1000])
    sender = Sender(
        store,
        HttpTransport(stub.endpoint, Secret(""), timeout_s=60),
        SendPolicy(batch_size=BATCH, batch_max_bytes=16 * MIB, http_compression=encoding),
    )
    started = time.perf_counter()
    assert sender.drain(), "the queue did not drain"
    elapsed = time.perf_counter() - started
    sender.transport.close()
    store.close()
    return elapsed, sender.stats.bytes_sent


def run_sender_alone(workdir: Path, events: list[dict], encoding: str) -> float:
    """The sender with a transport that discards: its own ceiling, no HTTP, no stub."""
    from phytrace_edge.ship.responses import Reply
    from phytrace_edge.ship.transport import FunctionTransport

    store = QueueStore.open(
        workdir / f"alone-{encoding}.db", limits=QueueLimits(max_bytes=8 * GIB), sync="normal"
    )
    for start in range(0, len(events), 1000):
        store.put_many(events[start : start + 1000])
    accept = Reply(200, {}, b'{"accepted": 0, "duplicates": 0, "rejected": []}')
    sender = Sender(
        store,
        FunctionTransport(lambda body, headers: accept),
        SendPolicy(batch_size=BATCH, batch_max_bytes=16 * MIB, http_compression=encoding),
    )
    started = time.perf_counter()
    assert sender.drain()
    elapsed = time.perf_counter() - started
    store.close()
    return elapsed


def run_baseline(stub: StubProcess, events: list[dict], encoding: str) -> tuple[float, int]:
    from phytrace_edge.queue.records import QueuedEvent

    batches = []
    for start in range(0, len(events), BATCH):
        chunk = [
            QueuedEvent(0, e["event_id"], orjson.dumps(e)) for e in events[start : start + BATCH]
        ]
        body = BodyEncoder(encoding).encode(
            b'{"events":[' + b",".join(q.json for q in chunk) + b"]}"
        )
        batches.append((body, request_headers(chunk, encoding)))
    client = httpx.Client(timeout=60)
    started = time.perf_counter()
    for body, headers in batches:
        assert (
            client.post(f"{stub.endpoint}/events", content=body, headers=headers).status_code == 200
        )
    elapsed = time.perf_counter() - started
    client.close()
    return elapsed, sum(len(body) for body, _ in batches)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()
    events = sample_events(args.events)
    print(
        f"{len(events)} events, {BATCH} per request, stub = uvicorn+starlette on loopback, "
        f"{args.rounds} round(s), medians",
        flush=True,
    )
    workdir = Path(tempfile.mkdtemp(prefix="bench-drain-"))
    rows = []
    try:
        for encoding in ("gzip", "zstd", "none"):
            ours, base, alone, wire = [], [], [], 0
            for round_ in range(args.rounds):
                alone.append(run_sender_alone(workdir, events, encoding))
                for kind in ("baseline", "ours"):
                    stub = StubProcess(workdir / f"stub-{encoding}-{kind}-{round_}.db").start()
                    try:
                        if kind == "ours":
                            elapsed, wire = run_ours(workdir, stub, events, encoding)
                            ours.append(elapsed)
                        else:
                            elapsed, _ = run_baseline(stub, events, encoding)
                            base.append(elapsed)
                        assert stub.stats()["unique"] == len(events)
                    finally:
                        stub.stop()
                    print(f"  {encoding} {kind}: {len(events) / elapsed:,.0f} ev/s", flush=True)
            ours_eps = len(events) / statistics.median(ours)
            base_eps = len(events) / statistics.median(base)
            alone_eps = len(events) / statistics.median(alone)
            mbps = wire / statistics.median(ours) / 1e6
            rows.append((encoding, ours_eps, base_eps, mbps, wire / len(events), alone_eps))
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    print(
        "\n| Content-Encoding | phytrace-edge drain (ev/s) | baseline: pre-encoded POSTs (ev/s) "
        "| ratio | wire MB/s (ours) | wire bytes/event | sender alone, no HTTP (ev/s) |"
    )
    print("|---|---|---|---|---|---|---|")
    for encoding, ours_eps, base_eps, mbps, per_event, alone_eps in rows:
        print(
            f"| {encoding} | {ours_eps:,.0f} | {base_eps:,.0f} | {ours_eps / base_eps:.2f}× "
            f"| {mbps:.1f} | {per_event:,.0f} | {alone_eps:,.0f} |"
        )


if __name__ == "__main__":
    main()
