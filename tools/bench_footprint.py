"""Footprint: what the bridge's processes hold on the robot, side by side with their
baselines in one run.

    .venv/bin/python tools/bench_footprint.py                    # about 3 minutes
    .venv-kilted/bin/python tools/bench_footprint.py --ros          # + run --input ros
    .venv/bin/python tools/bench_footprint.py --drain-events 432000   # a day at 5 Hz

For each process: RSS from ``/proc/<pid>/smaps_rollup`` split into anonymous (the heap,
thread stacks, caches) and file-backed (shared libraries, mapped files), the peak
(``VmHWM``), and CPU per second, sampled once a second after a warm-up. Rows:

- the floor: ``python -c`` sleeping, nothing imported;
- ``run --input sim`` with PhyCloud down (nothing listens) and up
  (``tools/fast_receiver.py``);
- ``drain`` of a large backlog, its peak against the empty-queue bridge's;
- with ``--ros`` (rclpy importable): ``run --input ros`` against a bare rclpy node
  subscribed to the same topics with empty callbacks, a Cyclone DDS robot publishing
  (``tools/bench_ros_cpu.py``'s);
- imports: each heavy module alone in a fresh process, above the floor.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS))
sys.path.insert(0, str(TOOLS.parent))

from bench_ingest import cpu_seconds  # noqa: E402 - tools/, beside this file
from bench_outage import Receiver, fill, simulated_events  # noqa: E402

from phytrace_edge.queue.peek import read_stats  # noqa: E402

MIB_KB = 1024
WARM_UP_S = 10.0
IMPORTS = [
    "sqlite3",
    "ssl",
    "numpy",
    "httpx",
    "tenacity",
    "orjson",
    "zstandard",
    "fastjsonschema",
    "prometheus_client",
    "tqdm",
    "phytrace_edge.queue.store",
    "phytrace_edge.ship.sender",
    "phytrace_edge.runtime.wiring",
    "phytrace_edge.sim.mock_ros.message_base",
]


class Footprint(NamedTuple):
    rss_mib: float
    anonymous_mib: float
    file_mib: float
    peak_mib: float
    cpu_per_s: float  # seconds of CPU per second: 0.05 is 5% of a core


def memory_kib(pid: int) -> dict[str, int]:
    """smaps_rollup's Rss/Anonymous and status's VmHWM, in KiB."""
    found = {}
    for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]:
        name, value, *_ = line.split()
        found[name.rstrip(":")] = int(value)
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            found["VmHWM"] = int(line.split()[1])
    return found


def watch(process: subprocess.Popen[bytes], seconds: float) -> Footprint:
    """Sample ``process`` once a second for ``seconds``: medians, the peak, CPU."""
    rss, anonymous = [], []
    cpu_before, started = cpu_seconds(process.pid), time.monotonic()
    peak, cpu = 0, 0.0
    while time.monotonic() - started < seconds:
        try:  # a drain ends by itself: the last sample stands
            found = memory_kib(process.pid)
            cpu = (cpu_seconds(process.pid) - cpu_before) / (time.monotonic() - started)
        except (FileNotFoundError, ProcessLookupError, KeyError):
            break
        rss.append(found["Rss"])
        anonymous.append(found["Anonymous"])
        peak = max(peak, found["VmHWM"])
        if process.poll() is not None:
            break
        time.sleep(1.0)  # sampling, not synchronisation
    if not rss:
        raise SystemExit(f"{process.args} ended before it could be measured")
    rss_mib, anonymous_mib = statistics.median(rss) / MIB_KB, statistics.median(anonymous) / MIB_KB
    return Footprint(rss_mib, anonymous_mib, rss_mib - anonymous_mib, peak / MIB_KB, cpu)


def measured(
    command: list[str],
    env: dict[str, str],
    seconds: float,
    ready: float,
    before_stop: Callable[[], None] = lambda: None,
) -> Footprint:
    """Start ``command``, let it warm up (``ready`` seconds), watch it, stop it."""
    process = subprocess.Popen(
        command, env=env, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    try:
        deadline = time.monotonic() + ready
        while time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.2)  # a benchmark's pacing: imports, discovery, first events
        found = watch(process, seconds)
        before_stop()
        return found
    finally:
        if process.stdin:
            process.stdin.close()
        process.terminate()
        process.wait(timeout=60)


def waiting(queue: Path) -> int:
    stats = read_stats(str(queue))
    return 0 if stats is None else stats.depth


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def bridge_env(queue: Path, endpoint: str, **extra: str) -> dict[str, str]:
    return {
        **os.environ,
        "PYTHONPATH": str(TOOLS.parent),
        "QUEUE_PATH": str(queue),
        "PHYCLOUD_ENDPOINT": endpoint,
        "LOG_LEVEL": "WARNING",
        **extra,
    }


def import_costs() -> list[tuple[str, float]]:
    """(module, MiB of RSS its import adds to a bare interpreter), each alone."""
    probe = (
        "import importlib, sys\n"
        "rss = lambda: int(open('/proc/self/statm').read().split()[1]) * 4 / 1024\n"
        "before = rss()\n"
        "importlib.import_module(sys.argv[1])\n"
        "print(rss() - before)\n"
    )
    costs = []
    for module in IMPORTS:
        result = subprocess.run(
            [sys.executable, "-c", probe, module],
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": str(TOOLS.parent)},
            timeout=120,
        )
        if result.returncode == 0:
            costs.append((module, float(result.stdout)))
    return costs


def row(name: str, ours: Footprint, baseline: Footprint | None = None) -> str:
    ratio = f" ({ours.rss_mib / baseline.rss_mib:.2f}×)" if baseline else ""
    return (
        f"| {name} | {ours.rss_mib:.1f}{ratio} | {ours.anonymous_mib:.1f} | "
        f"{ours.file_mib:.1f} | {ours.peak_mib:.1f} | {100 * ours.cpu_per_s:.1f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30, help="watched, per process")
    parser.add_argument("--drain-events", type=int, default=100_000)
    parser.add_argument("--ros", action="store_true", help="also run --input ros (rclpy)")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-footprint-"))
    rows = ["| process | RSS MiB (ratio) | anonymous | file-backed | peak | CPU % of a core |"]
    rows.append("|---|---|---|---|---|---|")
    try:
        floor = measured([sys.executable, "-c", "import sys; sys.stdin.read()"], {}, 5, 1)
        rows.append(row("floor: `python` doing nothing (baseline)", floor))
        if args.ros:
            rows.extend(ros_rows(workdir, args.seconds, floor))
        else:
            rows.extend(sim_rows(workdir, args, floor))
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    print("\n".join(rows))
    print("\n| import, alone | MiB above the floor |\n|---|---|")
    for module, cost in import_costs():
        print(f"| `{module}` | {cost:.1f} |")


def sim_rows(workdir: Path, args: argparse.Namespace, floor: Footprint) -> list[str]:
    """``run --input sim`` with PhyCloud down and up, and ``drain`` of a backlog."""
    python = sys.executable
    sim = [python, "-m", "phytrace_edge", "run", "--input", "sim"]
    down = f"http://127.0.0.1:{free_port()}/api/v1"  # nothing listens
    empty = measured(sim, bridge_env(workdir / "down.db", down), args.seconds, WARM_UP_S)
    receiver = Receiver()
    try:
        env = bridge_env(workdir / "up.db", receiver.endpoint)
        up = measured(sim, env, args.seconds, WARM_UP_S)
        backlog = workdir / "backlog.db"
        fill(backlog, simulated_events(), args.drain_events)
        env = bridge_env(backlog, receiver.endpoint)
        drained = measured([python, "-m", "phytrace_edge", "drain"], env, 600, 0.5)
        sent = args.drain_events - waiting(backlog)
    finally:
        receiver.stop()
    return [
        row("`run --input sim`, PhyCloud down", empty, floor),
        row("`run --input sim`, PhyCloud up", up, floor),
        row(f"`drain` of {args.drain_events:,} events (vs the row above)", drained, up),
        f"| ({sent:,} of them sent while watched) | | | | | |",
    ]


def ros_rows(workdir: Path, seconds: float, floor: Footprint) -> list[str]:
    """``run --input ros`` beside a bare rclpy node, a Cyclone DDS robot publishing."""
    try:
        import rclpy  # noqa: F401 - only to say early that rclpy is missing
    except ImportError:
        return ["| `run --input ros`: rclpy is not importable here (use .venv-kilted) | | | | | |"]
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": "218",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "PYTHONUNBUFFERED": "1",
    }
    from bench_ros_cpu import heard  # needs rclpy only in the bridge it asks

    script = str(TOOLS / "bench_ros_cpu.py")
    robot = subprocess.Popen(
        [sys.executable, script, "--child", "publish"], stdin=subprocess.PIPE, env=env
    )
    try:
        bare = measured([sys.executable, script, "--child", "bare"], env, seconds, WARM_UP_S)
        down = f"http://127.0.0.1:{free_port()}/api/v1"
        ours_env = bridge_env(
            workdir / "ros.db", down, **{k: env[k] for k in env if k.startswith("ROS_")}
        )
        command = [sys.executable, "-m", "phytrace_edge", "run", "--input", "ros"]
        said = []
        ours = measured(command, ours_env, seconds, WARM_UP_S, lambda: said.append(heard(ours_env)))
    finally:
        if robot.stdin:
            robot.stdin.close()
        robot.wait(timeout=30)
    return [
        row("bare rclpy node, empty callbacks (baseline for the next row)", bare, floor),
        row("`run --input ros`, PhyCloud down", ours, bare),
        f"| ({''.join(said)}) | | | | | |",
    ]


if __name__ == "__main__":
    main()
