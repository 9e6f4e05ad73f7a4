"""Memory soak: the bridge for an hour at 50 Hz while PhyCloud comes and goes, and the
trend of its RSS. A figure for docs/benchmarks.md, not a test.

    .venv/bin/python tools/soak_memory.py                       # an hour
    .venv/bin/python tools/soak_memory.py --minutes 10 --flap-s 120 --down-s 40
    .venv/bin/python tools/soak_memory.py --baseline-env MALLOC_ARENA_MAX=16  # side by side

``phytrace-edge run --input sim`` at SAMPLE_RATE_HZ=50 sends to
``tools/fast_receiver.py``, which, after a warm-up, is stopped for ``--down-s`` every
``--flap-s`` (an outage: the backlog builds, then drains) and started again on the same
port. Every ``--every-s`` a line: minutes, RSS and anonymous MiB
(``/proc/<pid>/smaps_rollup``), events waiting, PhyCloud up or down. At the end: the
median RSS of the first and the last tenth of the run, and the least-squares slope in
MiB per hour (flat is the goal).

With ``--probe``, the bridge runs under ``tools/soak_probe.py``, which writes the Python
heap, glibc's heap (used and free) and the fastest-growing allocation sites every minute
to ``probe.jsonl`` in the bridge's folder (printed at the end): what the RSS trend is made
of. With ``--baseline-env``, a second bridge runs beside the first with that setting in its
environment, against the same receiver and outages: one run, two columns.
"""

from __future__ import annotations

import argparse
import signal
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


def start_bridge(
    workdir: Path, endpoint: str, probe: bool, **extra: str
) -> subprocess.Popen[bytes]:
    """``run --input sim`` at 50 Hz on a queue of its own in ``workdir``."""
    workdir.mkdir()
    env = bridge_env(workdir / "queue.db", endpoint, SAMPLE_RATE_HZ="50", **extra)
    launcher = [str(TOOLS / "soak_probe.py"), str(workdir / "probe.jsonl")] if probe else []
    return subprocess.Popen(
        [sys.executable, *(launcher or ["-m", "phytrace_edge"]), "run", "--input", "sim"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=(workdir / "bridge.log").open("w"),
    )


def summary(name: str, points: list[tuple[float, float]]) -> str:
    tenth = max(1, len(points) // 10)
    first = statistics.median(y for _, y in points[:tenth])
    last = statistics.median(y for _, y in points[-tenth:])
    return (
        f"{name}: RSS first tenth {first:.1f} MiB, last tenth {last:.1f} MiB, "
        f"slope {slope_per_hour(points):+.2f} MiB/hour over {len(points)} samples"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60)
    parser.add_argument("--flap-s", type=float, default=240, help="an outage this often")
    parser.add_argument("--down-s", type=float, default=60, help="each outage this long")
    parser.add_argument("--every-s", type=float, default=30, help="a sample this often")
    parser.add_argument("--warm-up-s", type=float, default=20, help="before the first sample")
    parser.add_argument("--probe", action="store_true", help="tracemalloc and mallinfo2 inside")
    parser.add_argument(
        "--baseline-env",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="run a second bridge beside the first, with this in its environment",
    )
    args = parser.parse_args()
    # a SIGTERM ends the run like Ctrl-C: the bridges and the receiver are stopped
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    workdir = Path(tempfile.mkdtemp(prefix="soak-"))
    port = free_port()
    receiver: Receiver | None = Receiver(port=port)
    endpoint = f"http://127.0.0.1:{port}/api/v1"
    bridges = {"bridge": start_bridge(workdir / "bridge", endpoint, args.probe)}
    if args.baseline_env:
        extra = dict(item.split("=", 1) for item in args.baseline_env)
        bridges["baseline"] = start_bridge(workdir / "baseline", endpoint, args.probe, **extra)
        print(f"baseline: the same bridge with {' '.join(args.baseline_env)}", flush=True)
    time.sleep(args.warm_up_s)  # imports, the validator, the first events
    started = time.monotonic()
    next_flap, up_again = started + args.flap_s, 0.0
    points: dict[str, list[tuple[float, float]]] = {name: [] for name in bridges}
    columns = "".join(f"  {name:>8} RSS  anonymous  waiting" for name in bridges)
    print(f"minutes{columns}  PhyCloud", flush=True)
    try:
        while (elapsed := time.monotonic() - started) < args.minutes * 60:
            now = time.monotonic()
            if receiver is not None and now >= next_flap:
                receiver.stop()  # an outage
                receiver, up_again = None, now + args.down_s
            elif receiver is None and now >= up_again:
                receiver = Receiver(port=port)
                next_flap = now + args.flap_s
            line = f"{elapsed / 60:7.1f}"
            for name, bridge in bridges.items():
                found = memory_kib(bridge.pid)
                points[name].append((elapsed, found["Rss"] / 1024))
                line += (
                    f"  {found['Rss'] / 1024:12.1f}  {found['Anonymous'] / 1024:9.1f}  "
                    f"{waiting(workdir / name / 'queue.db'):7d}"
                )
            print(f"{line}  {'up' if receiver else 'down'}", flush=True)
            time.sleep(args.every_s)  # sampling, not synchronisation
    finally:
        for bridge in bridges.values():
            bridge.terminate()
        for bridge in bridges.values():
            bridge.wait(timeout=60)
        if receiver is not None:
            receiver.stop()
    for name, series in points.items():
        print(summary(name, series))
    if args.probe:
        print(f"probes: {workdir}/*/probe.jsonl")


if __name__ == "__main__":
    main()
