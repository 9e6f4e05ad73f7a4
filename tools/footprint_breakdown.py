"""Where the bridge's megabytes go: the parts of ``run --input sim`` put together one
at a time in one fresh process, the RSS after each, so each part's cost is measured
rather than guessed (docs/benchmarks.md, "Footprint"). A figure, not a test.

    .venv/bin/python tools/footprint_breakdown.py
    /path/to/robot-venv/bin/python tools/footprint_breakdown.py   # a core-only install

RSS is read from ``/proc/self/smaps_rollup`` (anonymous + file-backed). The steps, in
the order the service takes them: the interpreter; the standard library the service
uses; each third-party library; our own modules; compiling the UDM validator (its
peak, then after the free heap is handed back); the queue (open, then 20,000 events
put and claimed: SQLite's page cache and the zstd contexts); an HTTP client; the
service's threads. Each line: the step, RSS, anonymous, and the change.
"""

from __future__ import annotations

import importlib
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def memory_mib() -> tuple[float, float]:
    """(RSS, anonymous) of this process in MiB."""
    fields = {}
    with Path("/proc/self/smaps_rollup").open() as rollup:
        for line in rollup:
            parts = line.split()
            if len(parts) >= 2 and parts[0].endswith(":") and parts[1].isdigit():
                fields[parts[0][:-1]] = int(parts[1])
    return fields["Rss"] / 1024, fields["Anonymous"] / 1024


def peak_mib() -> float:
    with Path("/proc/self/status").open() as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return 0.0


class Steps:
    def __init__(self) -> None:
        self.last = memory_mib()[0]
        print(f"{'step':58} {'RSS':>7} {'anon':>7} {'change':>7}  (MiB)")
        self.show("the interpreter (python, site)")

    def show(self, name: str) -> None:
        rss, anonymous = memory_mib()
        print(f"{name:58} {rss:7.1f} {anonymous:7.1f} {rss - self.last:+7.1f}", flush=True)
        self.last = rss

    def step(self, name: str, action: Callable[[], object]) -> object:
        result = action()
        self.show(name)
        return result


def imports(*names: str) -> Callable[[], None]:
    def load() -> None:
        for name in names:
            importlib.import_module(name)

    return load


def queue_work(folder: Path) -> object:
    """Open a queue, put 20,000 simulated-robot-sized events in batches as the writer
    does, and claim and ack them as a sender does."""
    from phytrace_edge.builder.envelope import envelope
    from phytrace_edge.queue.store import QueueStore
    from phytrace_edge.udm.types import Built

    identity = {"source_id": "amr-1", "source_type": "amr"}
    store = QueueStore.open(folder / "queue.db")
    padding = {"note": "x" * 3000}  # about the size of a simulated robot's event
    for start in range(0, 20_000, 50):
        batch = [
            {**envelope(identity, "telemetry.periodic", 1_795_300_000 + i * 0.2), **padding}
            for i in range(start, start + 50)
        ]
        store.put_many([Built(event) for event in batch])
    while (claimed := store.claim_batch(500, 4 * 1024 * 1024)) is not None:
        store.ack(claimed)
    return store


def give_back_free_memory() -> None:
    from phytrace_edge.host_memory import give_back_free_memory as trim

    trim()


def thread_contexts(kept: list[object]) -> Callable[[], None]:
    """What ``queue.codecs`` holds per thread: the dictionary compressor (level 3) and
    a decompressor (python-zstandard's contexts must not be shared between threads)."""

    def make() -> None:
        import zstandard

        from phytrace_edge.queue.encoding.codecs import ZSTD_LEVEL, packaged_dictionary

        dictionary = zstandard.ZstdCompressionDict(packaged_dictionary()[1])
        compressor = zstandard.ZstdCompressor(level=ZSTD_LEVEL, dict_data=dictionary)
        frame = compressor.compress(b'{"event_id": "x", "pad": "%s"}' % (b"y" * 3000))
        decompressor = zstandard.ZstdDecompressor(dict_data=dictionary)
        decompressor.decompress(frame)
        kept.extend([compressor, decompressor])
        give_back_free_memory()  # what the contexts hold, not the buffers of the call

    return make


def wire(kept: list[object]) -> Callable[[], None]:
    """``ship.transport.BodyEncoder`` for zstd, used on a 500-event body (gzip keeps no
    context between requests)."""

    def make() -> None:
        from phytrace_edge.ship.transport import BodyEncoder

        encoder = BodyEncoder("zstd")
        encoder.encode(b"[" + b",".join([b'{"pad": "%s"}' % (b"y" * 3400)] * 500) + b"]")
        kept.append(encoder)
        give_back_free_memory()

    return make


def main() -> None:
    steps = Steps()
    steps.step(
        "standard library the service uses (logging, sqlite3, ssl...)",
        imports("logging", "sqlite3", "threading", "json", "ssl", "http.client", "uuid"),
    )
    steps.step("orjson, zstandard", imports("orjson", "zstandard"))
    steps.step("httpx (with httpcore, anyio, certifi, idna, h11)", imports("httpx"))
    loaded = sorted({"rich", "click", "pygments"} & set(sys.modules))
    if loaded:
        print(f"  (httpx also imported {', '.join(loaded)}: its command line, installed here)")
    steps.step("tenacity, fastjsonschema", imports("tenacity", "fastjsonschema"))
    steps.step("numpy (the mock rclpy layer: --input sim only)", imports("numpy"))
    steps.step(
        "phytrace_edge: service, wiring, sim source",
        imports(
            "phytrace_edge.runtime.wiring",
            "phytrace_edge.runtime.service",
            "phytrace_edge.ingest.sources.sim",
        ),
    )
    from phytrace_edge.udm.schema import prepare_validator

    before_peak = peak_mib()
    steps.step("UDM validator (the generated module, or compiled)", prepare_validator)
    print(f"  (peak while compiling: {peak_mib():.1f} MiB, was {before_peak:.1f})")
    steps.step("free heap handed back (malloc_trim)", give_back_free_memory)
    with tempfile.TemporaryDirectory() as folder:
        store = steps.step(
            "queue: 20,000 events put, claimed, acked", lambda: queue_work(Path(folder))
        )
        steps.step("free heap handed back (after a maintenance pass)", give_back_free_memory)
        kept: list[object] = []
        steps.step("zstd contexts of one more thread writing to the queue", thread_contexts(kept))
        steps.step("a wire compressor (HTTP_COMPRESSION=zstd), one per sending thread", wire(kept))
        import httpx

        # as ship/transport.py makes them: no SSL context for an http endpoint
        client = steps.step(
            "an httpx.Client for an http endpoint",
            lambda: httpx.Client(transport=httpx.HTTPTransport(verify=False, trust_env=False)),
        )
        steps.step(
            "an httpx.Client for an https endpoint (CA certificates)",
            lambda: httpx.Client(transport=httpx.HTTPTransport(verify=True, trust_env=False)),
        )
        stop = threading.Event()
        threads = [threading.Thread(target=stop.wait, daemon=True) for _ in range(8)]
        steps.step("8 idle threads (the service runs 6 to 8)", lambda: [t.start() for t in threads])
        stop.set()
        client.close()  # type: ignore[attr-defined]
        store.close()  # type: ignore[attr-defined]


if __name__ == "__main__":
    main()
