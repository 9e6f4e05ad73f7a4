"""After an outage: how soon PhyCloud sees the robot's present, and how much of the
outage's history survives a full queue.

    .venv/bin/pip install matplotlib                 # for the plot only
    .venv/bin/python tools/bench_lanes.py            # about 10 minutes
    .venv/bin/python tools/bench_lanes.py --hours 1 --thin-hours 2   # about a minute

1. **Time to current.** A queue holds H hours of a 10 Hz robot (1, 6 and 24 h, filled
   through the writer path on the robot's clock). The link comes back: a fast receiver
   (``tools/fast_receiver.py``) starts listening while the robot keeps queueing 10
   events a second. Measured: seconds from the receiver's start until it holds an
   event captured after it, for ``LIVE_SHARE=0`` (oldest first, what every shipper in
   the field does) against the default, side by side.
2. **History kept at a full queue.** 24 hours queued under a byte cap that holds a
   quarter of them, with ``QUEUE_ON_FULL=thin`` against ``drop_oldest``: the share of
   the outage's hours that still have periodic events, and the resolution left.

Prints the tables for docs/benchmarks.md and writes ``docs/bench_lanes.png``.
"""

from __future__ import annotations

import argparse
import itertools
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_outage import RATE_HZ, Receiver, bytes_on_disk, copy_queue, fill, row
from bench_outage import simulated_events as simulated

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.responses import Reply
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport
from phytrace_edge.udm.event import new_event_id
from phytrace_edge.units import GIB
from tests.processes import free_port

LIVE_MARK = b'"phase":"after"'
PLOT = Path(__file__).resolve().parent.parent / "docs" / "bench_lanes.png"


class Watch:
    """A transport that notes when a request first carried an event captured after
    the link came back (it is marked), and otherwise posts as usual."""

    def __init__(self, endpoint: str) -> None:
        self.http = HttpTransport(endpoint, Secret(""), timeout_s=30)
        self.present_at: float | None = None

    def post_events(self, body: bytes, headers: dict[str, str]) -> Reply:
        reply = self.http.post_events(body, headers)
        if self.present_at is None and reply.status == 200 and LIVE_MARK in body:
            self.present_at = time.monotonic()
        return reply

    def close(self) -> None:
        self.http.close()


def time_to_current(queue: Path, base: list[dict], live_share: float) -> float:
    """Seconds from the receiver's start until it holds an event captured after it."""
    port = free_port()
    store = QueueStore.open(queue, limits=QueueLimits(max_bytes=16 * GIB))
    watch = Watch(f"http://127.0.0.1:{port}/api/v1")
    policy = SendPolicy(
        http_compression="none", live_share=live_share, retry_min_s=0.05, retry_max_s=0.2
    )
    sender = Sender(store, watch, policy)  # type: ignore[arg-type]
    robot_stop = threading.Event()

    def robot() -> None:  # the robot keeps working: 10 events a second, marked
        for n in itertools.count():
            if robot_stop.wait(1 / RATE_HZ):
                return
            store.put({**base[n % len(base)], "event_id": new_event_id(), "phase": "after"})

    sending = threading.Thread(target=sender.run, daemon=True)
    sending.start()  # against nothing: the link is down
    time.sleep(1.0)  # the outage goes on for a moment: requests fail and are retried
    receiver = Receiver(port=port)
    back_at = time.monotonic()
    threading.Thread(target=robot, daemon=True).start()
    try:
        while watch.present_at is None and time.monotonic() - back_at < 900:
            time.sleep(0.01)
    finally:
        robot_stop.set()
        sender.stop.set()
        sending.join(timeout=60)
        receiver.stop()
        watch.close()
        store.close()
    return (watch.present_at or float("inf")) - back_at


def hours_kept(queue: Path, hours: float, on_full: str, cap: int, base: list[dict]) -> dict:
    """Queue ``hours`` under ``cap`` bytes; which outage hours keep periodic events."""
    fill(
        queue, base, int(hours * 3600 * RATE_HZ), limits=QueueLimits(max_bytes=cap, on_full=on_full)
    )
    with QueueStore.open(queue, limits=QueueLimits(max_bytes=cap, on_full=on_full)) as store:
        stats = store.stats()
        newest = stats.newest_queued_at or 0.0
        start = newest - hours * 3600
        rows = store._db.read(
            "SELECT queued_at, coalesce(newest_at, queued_at), count FROM events "
            "WHERE important = 0"
        )
    covered = set()
    per_hour = [0] * int(hours)
    for first, last, count in rows:
        for hour in range(int((first - start) // 3600), int((last - start) // 3600) + 1):
            if 0 <= hour < int(hours):
                covered.add(hour)
                per_hour[hour] += count / max(1, int((last - first) // 3600) + 1)
    return {
        "covered": len(covered) / int(hours),
        "per_hour": per_hour,
        "resolution": stats.resolution,
        "drops": stats.drops,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, nargs="+", default=[1, 6, 24])
    parser.add_argument("--thin-hours", type=float, default=24)
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-lanes-"))
    base = simulated()
    try:
        header = ("outage at 10 Hz", "backlog", "oldest first (LIVE_SHARE=0)", "default", "ratio")
        print("\n" + row(*header) + "\n|---|---|---|---|---|")
        for hours in args.hours:
            events = int(hours * 3600 * RATE_HZ)
            full = workdir / f"full-{hours:g}h" / "queue.db"
            full.parent.mkdir()
            fill(full, base, events)
            seconds = {}
            for share in (0.0, 0.2):
                scratch = workdir / f"scratch-{hours:g}-{share}" / "queue.db"
                scratch.parent.mkdir()
                copy_queue(full, scratch)
                seconds[share] = time_to_current(scratch, base, share)
                shutil.rmtree(scratch.parent)
            print(
                row(
                    f"{hours:g} h",
                    f"{events:,} events",
                    f"{seconds[0.0]:.2f} s",
                    f"{seconds[0.2]:.2f} s",
                    f"{seconds[0.0] / seconds[0.2]:.0f}×",
                ),
                flush=True,
            )
            shutil.rmtree(full.parent)

        hours = args.thin_hours
        sized = workdir / "sized" / "queue.db"
        sized.parent.mkdir()
        fill(sized, base, int(hours * 3600 * RATE_HZ))
        cap = max(2 * 1024 * 1024, bytes_on_disk(sized) // 4)
        shutil.rmtree(sized.parent)
        kept = {}
        for on_full in ("thin", "drop_oldest"):
            queue = workdir / on_full / "queue.db"
            queue.parent.mkdir()
            kept[on_full] = hours_kept(queue, hours, on_full, cap, base)
        title = f"{hours:g} h at 10 Hz, cap = 1/4 of it ({cap / 2**20:.0f} MiB)"
        print("\n" + row(title, "thin", "drop_oldest") + "\n|---|---|---|")
        print(
            row("outage hours with periodic history", *(f"{kept[k]['covered']:.0%}" for k in kept))
        )
        print(
            row(
                "resolution left",
                *(", ".join(f"{b['keeps']}" for b in kept[k]["resolution"]) or "all" for k in kept),
            )
        )
        print(row("dropped (by reason)", *(str(kept[k]["drops"]) for k in kept)))
        plot(kept, hours)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def plot(kept: dict, hours: float) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("(no plot: .venv/bin/pip install matplotlib)")
        return
    figure, axes = plt.subplots(figsize=(7, 2.6), dpi=100)
    for name, style in (("thin", "-"), ("drop_oldest", "--")):
        axes.step(range(int(hours)), kept[name]["per_hour"], style, where="post", label=name)
    axes.set_xlabel("hour of the outage")
    axes.set_ylabel("periodic events kept")
    axes.set_yscale("symlog")
    axes.legend()
    axes.set_title(f"A {hours:g} h outage in a queue that holds a quarter of it")
    figure.tight_layout()
    figure.savefig(PLOT)
    print(f"\nplot: {PLOT.relative_to(PLOT.parent.parent)}")


if __name__ == "__main__":
    main()
