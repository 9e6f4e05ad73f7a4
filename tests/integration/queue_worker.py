"""A child process for the queue's process-level tests (run as a script).

queue_worker.py put PATH START        put events START, START+1, ... one per transaction,
                                      printing each seq once put() returned
queue_worker.py drain PATH OUT        after "go" on stdin, claim+ack until the queue stays
                                      empty; the seqs it delivered go to OUT
queue_worker.py rss PATH N            report RSS (KiB) before and after queueing N events
"""

from __future__ import annotations

import sys
import time
import uuid
from pathlib import Path

import orjson

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.types import Built
from phytrace_edge.units import GIB, MIB

LIMITS = QueueLimits(max_bytes=GIB)
SEND_S = 0.002


def event(seq: int) -> dict:
    return {"event_id": str(uuid.UUID(int=seq)), "seq": seq, "pad": "p" * 200}


def put(path: str, start: int) -> None:
    store = QueueStore.open(path, limits=LIMITS)
    seq = start
    while True:
        store.put(event(seq))
        sys.stdout.write(f"{seq}\n")
        sys.stdout.flush()
        seq += 1


def drain(path: str, out: str) -> None:
    store = QueueStore.open(path, limits=LIMITS, busy_timeout_s=30)
    print("ready", flush=True)
    sys.stdin.readline()  # the test starts both drainers at once
    delivered = []
    idle_since = None
    while True:
        batch = store.claim_batch(37, MIB)
        if batch is None:
            idle_since = idle_since or time.monotonic()
            if time.monotonic() - idle_since > 0.5:  # the other drainer may still release
                break
            continue
        idle_since = None
        delivered.extend(orjson.loads(e.json)["seq"] for e in batch.events)
        time.sleep(SEND_S)  # the HTTP request a real sender makes while holding the lease
        store.ack(batch)
    Path(out).write_text("\n".join(map(str, delivered)))


def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS")


def rss(path: str, count: int) -> None:
    from phytrace_edge import run_simulation

    samples: list[dict] = []
    run_simulation(50, sink=samples.append)
    store = QueueStore.open(path, limits=LIMITS, sync="normal")
    store.put_many([Built(samples[0])])
    batch = store.claim_batch(1, MIB)
    store.ack(batch)
    before = rss_kib()
    for start in range(0, count, 1000):
        store.put_many(
            [
                Built({**samples[i % len(samples)], "event_id": str(uuid.uuid4())})
                for i in range(start, start + 1000)
            ]
        )
    for _ in range(10):  # the sender's work with a deep backlog
        store.ack(store.claim_batch(500, 64 * MIB))
    store.stats()
    print(
        orjson.dumps(
            {"before_kib": before, "after_kib": rss_kib(), "depth": store.stats().depth}
        ).decode()
    )


if __name__ == "__main__":
    mode, path, arg = sys.argv[1], sys.argv[2], sys.argv[3]
    {
        "put": lambda: put(path, int(arg)),
        "drain": lambda: drain(path, arg),
        "rss": lambda: rss(path, int(arg)),
    }[mode]()
