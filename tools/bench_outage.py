"""The 24-hour outage: 864,000 events queued while the link is down, then drained.

    .venv/bin/python tools/bench_outage.py                  # about 30 minutes
    .venv/bin/python tools/bench_outage.py --events 50000   # about 2 minutes

One run, side by side:

1. **At rest.** The queue is filled through the bridge's writer path (``put_many`` of
   one second of events at 10 Hz, the store's clock advancing with the robot's, so
   frames are sealed as in a real outage). Bytes on disk per event, against the same
   events kept one row each (frames off; measured on the first 100k and scaled).
2. **Opening the full queue** (what the bridge's start and ``drain`` pay) against an
   empty one.
3. **Memory.** The bridge's peak RSS (``phytrace-edge run``, simulated robot, PhyCloud
   unreachable) on the full queue against an empty one.
4. **Drain.** The full backlog drained by the sender with default settings, for each
   Content-Encoding, to (a) a minimal fast receiver (``tools/fast_receiver.py``) and
   (b) the project's stub; against (c) the raw-client ceiling: one httpx client
   POSTing the same batches, pre-encoded in memory, one at a time, with no queue.
5. **Latency.** 50 ms per request (cellular): one request in flight against two.
6. **Compression levels** of a 500-event batch.

Events are real simulated UDM events (a 10-minute drive at 10 Hz, cycled with fresh
time-ordered event ids).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import gzip
import os
import re
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import orjson
import zstandard
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from phytrace_edge import run_simulation
from phytrace_edge.config.settings import Settings
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import QueuedEvent
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.defaults import DEFAULT_BACKLOG_BATCH_SIZE
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import BodyEncoder, HttpTransport, events_body, request_headers
from phytrace_edge.udm.event import new_event_id
from phytrace_edge.udm.types import Built
from phytrace_edge.units import GIB, MIB
from tests.processes import StubProcess, free_port, python_env, wait_for

TOOLS = Path(__file__).resolve().parent
RATE_HZ = 10
ROWS_BASELINE_EVENTS = 100_000
ENCODINGS = ("gzip", "zstd", "none")


# ---------------------------------------------------------------- events


def simulated_events() -> list[dict]:
    """A 10-minute drive of the simulated robot, sampled at 10 Hz."""
    base: list[dict] = []
    run_simulation(6000, settings=Settings(sample_rate_hz=RATE_HZ), sink=base.append, seed=11)
    return base


def outage(base: list[dict], count: int, start: float) -> Iterator[tuple[float, list[dict]]]:
    """(robot time, one second of events) for ``count`` events, fresh ids."""
    for first in range(0, count, RATE_HZ):
        at = start + first / RATE_HZ
        seconds = [
            {**base[(first + i) % len(base)], "event_id": new_event_id(int(at * 1000) + i)}
            for i in range(min(RATE_HZ, count - first))
        ]
        yield at, seconds


# ---------------------------------------------------------------- at rest


def fill(
    path: Path,
    base: list[dict],
    count: int,
    frame_events: int | None = None,
    limits: QueueLimits | None = None,
) -> float:
    """Queue ``count`` events through ``put_many``, one second of events per commit;
    the fill's wall time."""
    clock = [time.time() - count / RATE_HZ]
    options = {"frame_events": frame_events} if frame_events else {}
    store = QueueStore.open(
        path,
        limits=limits or QueueLimits(max_bytes=16 * GIB),
        sync="normal",
        clock=lambda: clock[0],
        **options,
    )
    started = time.perf_counter()
    with tqdm(total=count, unit="ev", desc=f"fill {path.name}", leave=False) as bar:
        for at, second in outage(base, count, clock[0]):
            clock[0] = at
            store.put_many([Built(event) for event in second])
            bar.update(len(second))
    elapsed = time.perf_counter() - started
    store.reclaim_space(force=True)
    store.close()
    return elapsed


def bytes_on_disk(path: Path) -> int:
    """The database and its WAL (the fixed 4 MiB full-disk reserve is not per event)."""
    return sum(p.stat().st_size for p in (path, Path(f"{path}-wal")) if p.exists())


def open_seconds(path: Path, rounds: int = 3) -> float:
    times = []
    for _ in range(rounds):
        started = time.perf_counter()
        QueueStore.open(path, limits=QueueLimits(max_bytes=16 * GIB)).close()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


# ---------------------------------------------------------------- memory


def bridge_peak_rss(queue: Path, window_s: float = 15.0) -> float:
    """Peak RSS (MiB) of ``phytrace-edge run`` on ``queue`` with PhyCloud unreachable,
    over ``window_s`` once it has queued its first 20 events."""
    env = python_env(
        BRIDGE_INPUT="sim",
        QUEUE_PATH=str(queue),
        QUEUE_MAX_BYTES=str(16 * GIB),
        PHYCLOUD_ENDPOINT=f"http://127.0.0.1:{free_port()}/api/v1",  # nothing listens
        SOURCE_ID="bench-robot",
    )
    before = queued_total(queue)
    log = queue.with_suffix(".bridge.log").open("w")
    process = subprocess.Popen(
        [sys.executable, "-m", "phytrace_edge", "run"], stdout=log, stderr=log, env=env
    )
    try:
        wait_for(lambda: queued_total(queue) >= before + 20, 120, "the bridge to queue events")
        peak, until = 0, time.monotonic() + window_s
        while time.monotonic() < until:
            peak = max(peak, vm_kib(process.pid, "VmHWM"))
            time.sleep(0.5)  # sampling, not synchronisation
        return peak / 1024
    finally:
        process.terminate()
        process.wait(timeout=60)
        log.close()


def queued_total(queue: Path) -> int:
    with contextlib.suppress(sqlite3.Error):
        uri = f"file:{queue}?mode=ro"
        with contextlib.closing(sqlite3.connect(uri, uri=True, timeout=5)) as conn:
            row = conn.execute("SELECT value FROM counters WHERE name = 'queued_total'").fetchone()
            return int(row[0]) if row else 0
    return 0


def vm_kib(pid: int, field: str) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    match = re.search(rf"^{field}:\s+(\d+) kB", status, re.MULTILINE)
    return int(match.group(1)) if match else 0


# ---------------------------------------------------------------- drain


class Receiver:
    """tools/fast_receiver.py in its own process."""

    def __init__(self, delay_ms: float = 0, port: int = 0) -> None:
        command = [sys.executable, str(TOOLS / "fast_receiver.py"), "--delay-ms", str(delay_ms)]
        self.process = subprocess.Popen(
            [*command, "--port", str(port)],
            stdout=subprocess.PIPE,
            text=True,
            env=python_env(),
        )
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        self.url = line.split()[-1]
        self.endpoint = f"{self.url}/api/v1"

    def unique(self) -> int:
        return int(httpx.get(f"{self.url}/counts").json()["unique"])

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=30)


def drain(queue: Path, endpoint: str, encoding: str, **policy: int) -> tuple[float, int]:
    """Drain ``queue`` with the default send policy (but ``encoding``); (seconds,
    events)."""
    store = QueueStore.open(queue, limits=QueueLimits(max_bytes=16 * GIB))
    depth = store.counter("depth")
    sender = Sender(
        store,
        HttpTransport(endpoint, Secret(""), timeout_s=60),
        SendPolicy(http_compression=encoding, **policy),
    )
    started = time.perf_counter()
    with tqdm(total=depth, unit="ev", desc=f"drain {encoding}", leave=False) as bar:
        emptied = sender.drain(progress=bar.update)
    elapsed = time.perf_counter() - started
    sender.transport.close()
    store.close()
    if not emptied:
        raise SystemExit(f"the queue did not drain to {endpoint}")
    return elapsed, depth


def raw_client(endpoint: str, base: list[dict], count: int, encoding: str) -> float:
    """Seconds for one httpx client to POST ``count`` events in pre-encoded batches."""
    batches = []
    for _, second in outage(base, count, time.time()):
        batches.extend(second)
    size = DEFAULT_BACKLOG_BATCH_SIZE
    encoder = BodyEncoder(encoding)
    requests = []
    for first in range(0, len(batches), size):
        chunk = [
            QueuedEvent(0, e["event_id"], orjson.dumps(e)) for e in batches[first : first + size]
        ]
        requests.append((encoder.encode(events_body(chunk)), request_headers(chunk, encoding)))
    del batches
    with httpx.Client(timeout=60) as client:
        started = time.perf_counter()
        for body, headers in tqdm(requests, desc=f"raw {encoding}", leave=False):
            client.post(f"{endpoint}/events", content=body, headers=headers).raise_for_status()
        return time.perf_counter() - started


# ---------------------------------------------------------------- compression


def compression_levels(base: list[dict]) -> list[tuple[str, float, float]]:
    """(codec and level, ms to compress a backlog batch, wire bytes per event), over
    backlog batches from all along the drive."""
    size = DEFAULT_BACKLOG_BATCH_SIZE
    bodies = [
        events_body([QueuedEvent(0, e["event_id"], orjson.dumps(e)) for e in base[i : i + size]])
        for i in range(0, len(base) - size + 1, size)
    ]
    codecs: list[tuple[str, Callable[[bytes], bytes]]] = [
        *(
            (f"gzip {level}", functools.partial(gzip.compress, compresslevel=level, mtime=0))
            for level in (1, 3, 6, 9)
        ),
        *(
            (f"zstd {level}", zstandard.ZstdCompressor(level=level).compress)
            for level in (1, 2, 3, 6, 9)
        ),
    ]
    rows = []
    for name, compress in codecs:
        started = time.perf_counter()
        wire = sum(len(compress(body)) for body in bodies)
        elapsed = time.perf_counter() - started
        rows.append((name, elapsed / len(bodies) * 1000, wire / (len(bodies) * size)))
    return rows


# ---------------------------------------------------------------- report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=864_000)
    parser.add_argument("--latency-events", type=int, default=50_000)
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-outage-", dir=os.environ.get("BENCH_DIR")))
    print(f"simulating the robot... (work in {workdir})", flush=True)
    base = simulated_events()
    json_size = statistics.mean(len(orjson.dumps(e)) for e in base)
    try:
        report(args, workdir, base, json_size)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def report(args: argparse.Namespace, workdir: Path, base: list[dict], json_size: float) -> None:
    count = args.events
    full = workdir / "full" / "queue.db"
    full.parent.mkdir()
    fill_s = fill(full, base, count)
    rows_count = min(count, ROWS_BASELINE_EVENTS)
    rows_db = workdir / "rows" / "queue.db"
    rows_db.parent.mkdir()
    fill(rows_db, base, rows_count, frame_events=1)
    framed = bytes_on_disk(full) / count
    per_row = bytes_on_disk(rows_db) / rows_count

    empty = workdir / "empty" / "queue.db"
    empty.parent.mkdir()
    QueueStore.open(empty).close()
    open_full, open_empty = open_seconds(full), open_seconds(empty)

    scratch = workdir / "scratch" / "queue.db"
    scratch.parent.mkdir()
    copy_queue(full, scratch)
    rss_full = bridge_peak_rss(scratch)
    remove_queue(scratch)
    rss_empty = bridge_peak_rss(empty)

    print(f"\n{count:,} events of {json_size:,.0f} B JSON on average, filled in {fill_s:.0f} s")
    print("\n| at rest | ours: frames | one row per event | ratio |\n|---|---|---|---|")
    print(f"| bytes per event on disk | {framed:,.0f} | {per_row:,.0f} | {framed / per_row:.2f}× |")
    print(
        f"| {count:,} events on disk | {bytes_on_disk(full) / MIB:,.0f} MiB "
        f"| {per_row * count / MIB:,.0f} MiB | |"
    )
    print("\n| | full queue | empty queue | ratio |\n|---|---|---|---|")
    print(
        row(
            "open (start, `drain`)",
            f"{open_full:.3f} s",
            f"{open_empty:.3f} s",
            f"{open_full / open_empty:.1f}×",
        )
    )
    print(
        row(
            "bridge peak RSS",
            f"{rss_full:.1f} MiB",
            f"{rss_empty:.1f} MiB",
            f"{rss_full / rss_empty:.2f}×",
        )
    )

    raw_count = min(count, ROWS_BASELINE_EVENTS)
    print(
        "\n| Content-Encoding | drain to fast receiver | ev/s | raw client (ev/s) | ratio "
        "| drain to the stub | ev/s |\n|---|---|---|---|---|---|---|",
        flush=True,
    )
    for encoding in ENCODINGS:
        receiver = Receiver()
        try:
            copy_queue(full, scratch)
            fast_s, drained = drain(scratch, receiver.endpoint, encoding)
            assert receiver.unique() == count, "the fast receiver is missing events"
        finally:
            receiver.stop()
        receiver = Receiver()
        try:
            raw_s = raw_client(receiver.endpoint, base, raw_count, encoding)
        finally:
            receiver.stop()
        stub = StubProcess(workdir / f"stub-{encoding}.db").start()
        try:
            copy_queue(full, scratch)
            stub_s, _ = drain(scratch, stub.endpoint, encoding)
            assert stub.stats()["unique"] == count, "the stub is missing events"
        finally:
            stub.stop()
        with contextlib.suppress(FileNotFoundError):
            (workdir / f"stub-{encoding}.db").unlink()
        raw_eps = raw_count / raw_s
        print(
            f"| {encoding} | {fast_s:.1f} s | {drained / fast_s:,.0f} | {raw_eps:,.0f} "
            f"| {drained / fast_s / raw_eps:.2f}× | {stub_s:.1f} s | {drained / stub_s:,.0f} |",
            flush=True,
        )

    latency_count = min(count, args.latency_events)
    latency_db = workdir / "latency" / "queue.db"
    latency_db.parent.mkdir()
    print(
        f"\n| 50 ms per request, {latency_count:,} events, zstd | ev/s | ratio |\n|---|---|---|",
        flush=True,
    )
    rates = {}
    for in_flight in (1, 2, 4):
        fill(latency_db, base, latency_count)
        receiver = Receiver(delay_ms=50)
        try:
            seconds, drained = drain(
                latency_db, receiver.endpoint, "zstd", requests_in_flight=in_flight
            )
        finally:
            receiver.stop()
        remove_queue(latency_db)
        rates[in_flight] = drained / seconds
        print(
            f"| {in_flight} request(s) in flight | {rates[in_flight]:,.0f} "
            f"| {rates[in_flight] / rates[1]:.2f}× |",
            flush=True,
        )

    print(
        f"\n| compression of a {DEFAULT_BACKLOG_BATCH_SIZE}-event batch | ms | wire bytes/event |"
        "\n|---|---|---|"
    )
    for name, ms, per_event in compression_levels(base):
        print(f"| {name} | {ms:.1f} | {per_event:,.0f} |")


def row(*cells: str) -> str:
    """One row of a markdown table."""
    return "| " + " | ".join(cells) + " |"


def copy_queue(source: Path, target: Path) -> None:
    remove_queue(target)
    for path in source.parent.glob(source.name + "*"):
        if path.is_file():
            shutil.copy2(path, target.parent / path.name.replace(source.name, target.name, 1))


def remove_queue(path: Path) -> None:
    for leftover in path.parent.glob(path.name + "*"):
        if leftover.is_file():
            leftover.unlink()
        else:
            shutil.rmtree(leftover, ignore_errors=True)


if __name__ == "__main__":
    main()
