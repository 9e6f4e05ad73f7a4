"""Memory soak: the bridge for an hour at 50 Hz while PhyCloud comes and goes, and the
trend of its RSS. A figure for docs/benchmarks.md, not a test.

    .venv/bin/python tools/soak_memory.py                       # an hour
    .venv/bin/python tools/soak_memory.py --minutes 10 --flap-s 120 --down-s 40

``phytrace-edge run --input sim`` at SAMPLE_RATE_HZ=50 sends to
``tools/fast_receiver.py``, which, after a warm-up, is stopped for ``--down-s`` every
``--flap-s`` (an outage: the backlog builds, then drains) and started again on the same
port. Every ``--every-s`` a line: minutes, RSS and anonymous MiB
(``/proc/<pid>/smaps_rollup``), events waiting, PhyCloud up or down. At the end: the
median RSS of the first and the last tenth of the run, and the least-squares slope in
MiB per hour (flat is the goal).

With ``--probe``, the bridge runs under ``tools/soak_probe.py``, which writes the Python
heap, glibc's heap (used and free) and the fastest-growing allocation sites every minute
to ``probe.jsonl`` in the run's folder (printed at the end): what the RSS trend is made of.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS))
sys.path.insert(0, str(TOOLS.parent))

from bench_footprint import bridge_env, free_port, memory_kib, waiting  # noqa: E402
from bench_outage import Receiver  # noqa: E402


def slope_per_hour(points: list[tuple[float, float]]) -> float:
    """Least-squares slope of (seconds, MiB), in MiB per hour. Pure."""
    xs, ys = [x for x, _ in points], [y for _, y in points]
    mean_x, mean_y = statistics.fmean(xs), statistics.fmean(ys)
    spread = sum((x - mean_x) ** 2 for x in xs)
    if not spread:
        return 0.0
    return 3600 * sum((x - mean_x) * (y - mean_y) for x, y in points) / spread


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60)
    parser.add_argument("--flap-s", type=float, default=240, help="an outage this often")
    parser.add_argument("--down-s", type=float, default=60, help="each outage this long")
    parser.add_argument("--every-s", type=float, default=30, help="a sample this often")
    parser.add_argument("--warm-up-s", type=float, default=20, help="before the first sample")
    parser.add_argument("--probe", action="store_true", help="tracemalloc and mallinfo2 inside")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="soak-"))
    port = free_port()
    receiver: Receiver | None = Receiver(port=port)
    endpoint = f"http://127.0.0.1:{port}/api/v1"
    env = bridge_env(workdir / "queue.db", endpoint, SAMPLE_RATE_HZ="50")
    launcher = [str(TOOLS / "soak_probe.py"), str(workdir / "probe.jsonl")] if args.probe else []
    bridge = subprocess.Popen(
        [sys.executable, *(launcher or ["-m", "phytrace_edge"]), "run", "--input", "sim"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=(workdir / "bridge.log").open("w"),
    )
    time.sleep(args.warm_up_s)  # imports, the validator, the first events
    started = time.monotonic()
    next_flap, up_again = started + args.flap_s, 0.0
    points: list[tuple[float, float]] = []
    print("minutes  RSS MiB  anonymous  waiting  PhyCloud", flush=True)
    try:
        while (elapsed := time.monotonic() - started) < args.minutes * 60:
            now = time.monotonic()
            if receiver is not None and now >= next_flap:
                receiver.stop()  # an outage
                receiver, up_again = None, now + args.down_s
            elif receiver is None and now >= up_again:
                receiver = Receiver(port=port)
                next_flap = now + args.flap_s
            found = memory_kib(bridge.pid)
            rss = found["Rss"] / 1024
            points.append((elapsed, rss))
            print(
                f"{elapsed / 60:7.1f}  {rss:7.1f}  {found['Anonymous'] / 1024:9.1f}  "
                f"{waiting(workdir / 'queue.db'):7d}  {'up' if receiver else 'down'}",
                flush=True,
            )
            time.sleep(args.every_s)  # sampling, not synchronisation
    finally:
        bridge.terminate()
        bridge.wait(timeout=60)
        if receiver is not None:
            receiver.stop()
    tenth = max(1, len(points) // 10)
    first = statistics.median(y for _, y in points[:tenth])
    last = statistics.median(y for _, y in points[-tenth:])
    print(f"RSS: first tenth {first:.1f} MiB, last tenth {last:.1f} MiB")
    print(f"slope: {slope_per_hour(points):+.2f} MiB/hour over {len(points)} samples")
    if args.probe:
        print(f"probes: {workdir / 'probe.jsonl'}")


if __name__ == "__main__":
    main()
