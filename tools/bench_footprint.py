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

    .venv/bin/python tools/bench_footprint.py --against b84e329 [--after HEAD]

measures two revisions side by side in one run (``tools/revisions.py``): each row's
process once from each tree in turn, each on its own queue filled by its own code (the
floor, the receiver and the bare rclpy node are shared); each cell is before / after
(after ÷ before).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
import sqlite3
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS))
sys.path.insert(0, str(TOOLS.parent))

import revisions  # noqa: E402 - tools/, beside this file
from bench_ingest import cpu_seconds  # noqa: E402
from bench_outage import Receiver  # noqa: E402

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

# tools/bench_outage.py's fill, run by the tree measured: ``count`` real simulated events
# (a 10-minute drive at 10 Hz, cycled with fresh ids), one second of them per put_many,
# the store's clock advancing with the robot's so that frames are sealed
FILL = """
import sys, time
from phytrace_edge import run_simulation
from phytrace_edge.config.settings import Settings
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.event import new_event_id
try:  # put_many takes Built (event, important) since phytrace_edge.udm.types
    from phytrace_edge.udm.types import Built
    wrap = lambda event: Built(event, False)
except ImportError:  # before: plain events
    wrap = lambda event: event
path, count, rate = sys.argv[1], int(sys.argv[2]), 10
base = []
run_simulation(6000, settings=Settings(sample_rate_hz=rate), sink=base.append, seed=11)
start = time.time() - count / rate
clock = [start]
limits = QueueLimits(max_bytes=16 << 30)
store = QueueStore.open(path, limits=limits, sync="normal", clock=lambda: clock[0])
for first in range(0, count, rate):
    clock[0] = start + first / rate
    store.put_many([
        wrap({**base[(first + i) % len(base)], "event_id": new_event_id(int(clock[0] * 1000) + i)})
        for i in range(min(rate, count - first))
    ])
store.reclaim_space(force=True)
store.close()
"""


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
        raise SystemExit(f"{process.args!r} ended before it could be measured")
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
    """The queue's depth counter, read with sqlite3 alone (any revision's queue)."""
    with contextlib.closing(sqlite3.connect(f"file:{queue}?mode=ro", uri=True)) as conn:
        found = conn.execute("SELECT value FROM counters WHERE name = 'depth'").fetchone()
    return int(found[0]) if found else 0


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def bridge_env(tree: revisions.Tree, queue: Path, endpoint: str, **extra: str) -> dict[str, str]:
    return revisions.env(
        tree, QUEUE_PATH=str(queue), PHYCLOUD_ENDPOINT=endpoint, LOG_LEVEL="WARNING", **extra
    )


def import_costs(trees: list[revisions.Tree]) -> list[tuple[str, list[float | None]]]:
    """(module, MiB of RSS its import adds to a bare interpreter, per tree), each alone;
    None where the tree has no such module."""
    probe = (
        "import importlib, sys\n"
        "rss = lambda: int(open('/proc/self/statm').read().split()[1]) * 4 / 1024\n"
        "before = rss()\n"
        "importlib.import_module(sys.argv[1])\n"
        "print(rss() - before)\n"
    )
    costs = []
    for module in IMPORTS:
        found: list[float | None] = []
        for tree in trees:
            result = subprocess.run(
                [sys.executable, "-c", probe, module],
                capture_output=True,
                text=True,
                env=revisions.env(tree),
                timeout=120,
            )
            found.append(float(result.stdout) if result.returncode == 0 else None)
        if any(cost is not None for cost in found):
            costs.append((module, found))
    return costs


def row(name: str, ours: Footprint, baseline: Footprint | None = None) -> str:
    ratio = f" ({ours.rss_mib / baseline.rss_mib:.2f}×)" if baseline else ""
    return (
        f"| {name} | {ours.rss_mib:.1f}{ratio} | {ours.anonymous_mib:.1f} | "
        f"{ours.file_mib:.1f} | {ours.peak_mib:.1f} | {100 * ours.cpu_per_s:.1f} |"
    )


def compared(name: str, before: Footprint, after: Footprint) -> str:
    """A row of two revisions: each cell before / after (after ÷ before)."""
    cells = []
    for b, a, scale in zip(before, after, (1, 1, 1, 1, 100), strict=True):  # CPU in %
        cells.append(f"{b * scale:.1f} / {a * scale:.1f}" + (f" ({a / b:.2f}×)" if b else ""))
    return f"| {name} | {' | '.join(cells)} |"


def line(name: str, ours: list[Footprint], baseline: Footprint | None = None) -> str:
    """One tree: ``row`` against its baseline; two: ``compared``."""
    return row(name, ours[0], baseline) if len(ours) == 1 else compared(name, *ours)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30, help="watched, per process")
    parser.add_argument("--drain-events", type=int, default=100_000)
    parser.add_argument("--ros", action="store_true", help="also run --input ros (rclpy)")
    revisions.add_arguments(parser)
    args = parser.parse_args()
    with revisions.trees(args) as (workdir, trees):
        floor = measured([sys.executable, "-c", "import sys; sys.stdin.read()"], {}, 5, 1)
        if len(trees) > 1:
            print(f"\n{revisions.title(trees)}; each cell before / after (after ÷ before)\n")
        rows = ["| process | RSS MiB (ratio) | anonymous | file-backed | peak | CPU % of a core |"]
        rows.append("|---|---|---|---|---|---|")
        rows.append(row("floor: `python` doing nothing (baseline)", floor))
        if args.ros:
            rows.extend(ros_rows(workdir, trees, args.seconds, floor))
        else:
            rows.extend(sim_rows(workdir, trees, args, floor))
        costs = import_costs(trees)
    print("\n".join(rows))
    if len(trees) == 1:
        print("\n| import, alone | MiB above the floor |\n|---|---|")
    else:
        print("\n| import, alone | MiB above the floor, before | after | after − before |")
        print("|---|---|---|---|")
    for module, found in costs:
        cells = ["–" if cost is None else f"{cost:.1f}" for cost in found]
        if len(found) > 1:
            before, after = found
            cells.append("–" if before is None or after is None else f"{after - before:+.1f}")
        print(f"| `{module}` | {' | '.join(cells)} |")


def sim_rows(
    workdir: Path, trees: list[revisions.Tree], args: argparse.Namespace, floor: Footprint
) -> list[str]:
    """``run --input sim`` with PhyCloud down and up, and ``drain`` of a backlog."""
    python = sys.executable
    sim = [python, "-m", "phytrace_edge", "run", "--input", "sim"]
    down = f"http://127.0.0.1:{free_port()}/api/v1"  # nothing listens
    watching = (args.seconds, WARM_UP_S)
    empty = [
        measured(sim, bridge_env(tree, workdir / f"down-{tree.name}.db", down), *watching)
        for tree in trees
    ]
    backlogs = [workdir / f"backlog-{tree.name}.db" for tree in trees]
    for tree, backlog in zip(trees, backlogs, strict=True):
        print(f"filling a backlog of {args.drain_events:,} events ({tree.commit}) ...", flush=True)
        command = [python, "-c", FILL, str(backlog), str(args.drain_events)]
        subprocess.run(command, env=revisions.env(tree), check=True)
    receiver = Receiver()
    try:
        up = [
            measured(
                sim,
                bridge_env(tree, workdir / f"up-{tree.name}.db", receiver.endpoint),
                *watching,
            )
            for tree in trees
        ]
        drained = [
            measured(
                [python, "-m", "phytrace_edge", "drain"],
                bridge_env(tree, backlog, receiver.endpoint),
                600,
                0.5,
            )
            for tree, backlog in zip(trees, backlogs, strict=True)
        ]
    finally:
        receiver.stop()
    against_up = " (vs the row above)" if len(trees) == 1 else ""
    sent = " / ".join(f"{args.drain_events - waiting(backlog):,}" for backlog in backlogs)
    return [
        line("`run --input sim`, PhyCloud down", empty, floor),
        line("`run --input sim`, PhyCloud up", up, floor),
        line(f"`drain` of {args.drain_events:,} events{against_up}", drained, up[0]),
        f"| ({sent} of them sent while watched) | | | | | |",
    ]


def ros_rows(
    workdir: Path, trees: list[revisions.Tree], seconds: float, floor: Footprint
) -> list[str]:
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

    said: list[str] = []

    def asking(prefix: str, tree_env: dict[str, str]) -> Callable[[], None]:
        return lambda: said.append(prefix + heard(tree_env))

    script = str(TOOLS / "bench_ros_cpu.py")
    robot = subprocess.Popen(
        [sys.executable, script, "--child", "publish"], stdin=subprocess.PIPE, env=env
    )
    ours: list[Footprint] = []
    try:
        bare = measured([sys.executable, script, "--child", "bare"], env, seconds, WARM_UP_S)
        down = f"http://127.0.0.1:{free_port()}/api/v1"
        ros = {k: env[k] for k in env if k.startswith("ROS_")}
        command = [sys.executable, "-m", "phytrace_edge", "run", "--input", "ros"]
        for tree in trees:
            tree_env = bridge_env(tree, workdir / f"ros-{tree.name}.db", down, **ros)
            ask = asking(f"{tree.name}: " if len(trees) > 1 else "", tree_env)
            ours.append(measured(command, tree_env, seconds, WARM_UP_S, ask))
    finally:
        if robot.stdin:
            robot.stdin.close()
        robot.wait(timeout=30)
    return [
        row("bare rclpy node, empty callbacks (baseline for the next row)", bare, floor),
        line("`run --input ros`, PhyCloud down", ours, bare),
        f"| ({'; '.join(said)}) | | | | | |",
    ]


if __name__ == "__main__":
    main()
