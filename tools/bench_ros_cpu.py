"""The `ros` input's CPU beside a bare rclpy node with empty callbacks, side by side in
one run, at a realistic robot's load (needs rclpy and the message packages: ROS 2
sourced, or the Kilted wheels' venv; the robot is a Cyclone DDS publisher speaking
ROS 2's wire types, run by a Python that has cyclonedds: ``--robot-python``, by default
this one if it has it, else the checkout's ``.venv``).

    source /opt/ros/jazzy/setup.bash && export RMW_IMPLEMENTATION=rmw_cyclonedds_cpp
    .venv/bin/python tools/bench_ros_cpu.py --seconds 60
    .venv-kilted/bin/python tools/bench_ros_cpu.py --seconds 60   # rclpy 9.1, Fast DDS

Prints a table: % of one core for each, and the ratio (goal: <= 1.0).

``--incident`` measures what an armed incident window costs (issue 35), at two rate
sets of the six window topics (``realistic``: odometry 50 Hz, IMU 200 Hz, joint states
100 Hz, scan 10 Hz, /cmd_vel 20 Hz, battery 1 Hz; ``demanding``: IMU 400 Hz, joint
states 500 Hz), each process measured in turn, the rows interleaved, ``--rounds``
times: the bare rclpy node; ``run --input ros`` with INCIDENT_RECORDING=false (the
state topics taken at the tick) and =true (the window armed: every message of the
window topics taken at the tick and kept for INCIDENT_BEFORE_S); at the demanding rates also
with a 120 s window, which the 16 MiB byte bound cuts; and, unless ``--no-dds``,
``run --input dds`` off and on (run by the robot's Python, which has cyclonedds). For
each: % of one core, RSS at the end and its peak (VmHWM), what the bridge heard per
second and what its window buffer held (from ``status``), the machine's load.

    .venv-kilted/bin/python tools/bench_ros_cpu.py --incident --seconds 60 --rounds 2
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# about 193 messages a second, as the issue measured on a delivery robot
RATES_HZ = {
    "/odom": 50,
    "/imu/data": 100,
    "/joint_states": 20,
    "/scan": 10,
    "/cmd_vel": 10,
    "/gps/fix": 1,
    "/battery_state": 1,
    "/diagnostics": 1,
}
# issue 35: the incident window's six topics (INCIDENT_TOPICS' default)
WINDOW_RATES_HZ = {
    "realistic": {
        "/odom": 50,
        "/imu/data": 200,
        "/joint_states": 100,
        "/scan": 10,
        "/cmd_vel": 20,
        "/battery_state": 1,
    },
    "demanding": {
        "/odom": 50,
        "/imu/data": 400,
        "/joint_states": 500,
        "/scan": 10,
        "/cmd_vel": 20,
        "/battery_state": 1,
    },
}
RATE_SETS = {"default": RATES_HZ, **WINDOW_RATES_HZ}
TYPES = {
    "/odom": ("nav_msgs.msg", "Odometry"),
    "/imu/data": ("sensor_msgs.msg", "Imu"),
    "/joint_states": ("sensor_msgs.msg", "JointState"),
    "/scan": ("sensor_msgs.msg", "LaserScan"),
    "/cmd_vel": ("geometry_msgs.msg", "Twist"),
    "/gps/fix": ("sensor_msgs.msg", "NavSatFix"),
    "/battery_state": ("sensor_msgs.msg", "BatteryState"),
    "/diagnostics": ("diagnostic_msgs.msg", "DiagnosticArray"),
}
WARM_UP_S = 8.0
MIB = 1024 * 1024


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def memory_kib(pid: int) -> dict[str, int]:
    """VmRSS and VmHWM (the peak RSS) of a process, in KiB."""
    found = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            found[key] = int(value.split()[0])
    return found


def publish(stop: threading.Event, rates: dict[str, int]) -> None:
    """The robot: each topic at its rate, Cyclone DDS with ROS 2's names and types."""
    from bench_ingest import publish_load  # tools/, beside this file: needs cyclonedds

    publish_load(stop, rates)


def bare(stop: threading.Event, rates: dict[str, int]) -> None:
    """The baseline: an rclpy node subscribed to the same topics, callbacks empty."""
    import importlib

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.signals import SignalHandlerOptions

    # stops on SIGTERM like the bridge: its own handler, none of rclpy's
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.set())
    node = rclpy.create_node("bare_subscriber")
    for topic in rates:
        module, name = TYPES[topic]
        message = getattr(importlib.import_module(module), name)
        node.create_subscription(message, topic, lambda msg: None, qos_profile_sensor_data)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.1)
    rclpy.try_shutdown()


@dataclass
class Figures:
    """One process measured: % of one core, RSS at the end and its peak (MiB), what a
    bridge heard per second by topic and its incident figures (from ``status``), the
    machine's 1-minute load before and after, the robot's own % of a core."""

    cpu_pct: float
    rss_mib: float
    peak_mib: float
    heard_per_s: dict[str, float] = field(default_factory=dict)
    incidents: dict[str, Any] = field(default_factory=dict)
    load: tuple[float, float] = (0.0, 0.0)
    robot_cpu_pct: float = 0.0


def measure(
    command: list[str],
    env: dict[str, str],
    seconds: float,
    warm_up_s: float = WARM_UP_S,
    robot_pid: int | None = None,
) -> Figures:
    """% of one core a process uses over ``seconds``, after its warm-up; its RSS."""
    bridge = "QUEUE_PATH" in env
    process = subprocess.Popen(command, stdin=subprocess.PIPE, env=env)
    try:
        time.sleep(warm_up_s)  # a benchmark's pacing: imports, discovery, a full window
        first = bridge_status(env) if bridge else {}
        load_before = os.getloadavg()[0]
        robot_before = cpu_seconds(robot_pid) if robot_pid else 0.0
        before, started = cpu_seconds(process.pid), time.monotonic()
        time.sleep(seconds)
        if process.poll() is not None:  # its figures would be a dead process's
            raise RuntimeError(f"{' '.join(command)} exited ({process.returncode})")
        used, elapsed = cpu_seconds(process.pid) - before, time.monotonic() - started
        robot_used = cpu_seconds(robot_pid) - robot_before if robot_pid else 0.0
        memory = memory_kib(process.pid)
        load_after = os.getloadavg()[0]
        last = bridge_status(env) if bridge else {}
        figures = Figures(
            cpu_pct=100 * used / elapsed,
            rss_mib=memory["VmRSS"] / 1024,
            peak_mib=memory["VmHWM"] / 1024,
            load=(load_before, load_after),
            robot_cpu_pct=100 * robot_used / elapsed,
        )
        if bridge:
            figures.heard_per_s = heard_per_s(first, last)
            figures.incidents = last.get("incidents", {})
            print(heard(last), flush=True)  # an idle bridge must not pass for a cheap one
        return figures
    finally:
        process.terminate()
        process.wait(timeout=30)


def bridge_status(env: dict[str, str]) -> dict[str, Any]:
    """The running bridge's ``status --json``, and when it was read (``at``)."""
    status = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "status", "--json"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    document = json.loads(status.stdout) if status.stdout else {}
    return {**document, "at": time.monotonic()}


def heard_per_s(first: dict[str, Any], last: dict[str, Any]) -> dict[str, float]:
    """Messages a second each topic's reader handed over between two statuses (as
    recent as the heartbeat they read: both as late)."""
    elapsed = last["at"] - first["at"]
    before, after = first.get("topics", {}), last.get("topics", {})
    return {
        topic: (after[topic].get("received", 0) - before.get(topic, {}).get("received", 0))
        / elapsed
        for topic in after
        if topic in TYPES and elapsed > 0
    }


def heard(status: dict[str, Any]) -> str:
    """The messages the running bridge received per topic, from its status."""
    topics = status.get("topics", {})
    counts = ", ".join(f"{t} {topics[t].get('received', 0)}" for t in TYPES if t in topics)
    return f"the bridge heard: {counts or 'nothing'}"


def robot_python(given: str) -> str:
    """A Python with cyclonedds, for the robot (and the ``dds`` input)."""
    if given:
        return given
    if importlib.util.find_spec("cyclonedds") is not None:
        return sys.executable
    return str(ROOT / ".venv" / "bin" / "python")


def domain_env() -> dict[str, str]:
    return {  # a private domain, its discovery confined to loopback
        **os.environ,
        "ROS_DOMAIN_ID": "217",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOCALHOST_ONLY": "1",
        "PYTHONUNBUFFERED": "1",
    }


def bridge_env(env: dict[str, str], queue: Path, **settings: str) -> dict[str, str]:
    return {
        **env,
        "PHYCLOUD_ENDPOINT": "http://127.0.0.1:9/api/v1",  # nobody: sends fail fast
        "QUEUE_PATH": str(queue),
        "SAMPLE_RATE_HZ": "5",
        "HEALTH_EVENT_INTERVAL_S": "0",
        "LOG_LEVEL": "ERROR",
        **settings,
    }


def start_robot(python: str, rates: str, env: dict[str, str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [python, __file__, "--child", "publish", "--rates", rates], stdin=subprocess.PIPE, env=env
    )


def stop_robot(robot: subprocess.Popen[bytes]) -> None:
    assert robot.stdin is not None
    robot.stdin.close()
    robot.wait(timeout=30)


def ros_cpu(seconds: float, robot: str) -> None:
    """The bare rclpy node, then ``run --input ros``, at ``RATES_HZ``."""
    workdir = Path(tempfile.mkdtemp(prefix="bench-ros-"))
    env = domain_env()
    publisher = start_robot(robot, "default", env)
    try:
        command = [sys.executable, __file__, "--child", "bare", "--rates", "default"]
        baseline = measure(command, env, seconds).cpu_pct
        command = [sys.executable, "-m", "phytrace_edge", "run", "--input", "ros"]
        ours = measure(command, bridge_env(env, workdir / "queue.db"), seconds).cpu_pct
    finally:
        stop_robot(publisher)
        shutil.rmtree(workdir, ignore_errors=True)
    load = sum(RATES_HZ.values())
    print(f"| `ros` input, {load} messages/s, {seconds:.0f} s | CPU, % of one core |")
    print("|---|---|")
    print(f"| bare rclpy node, empty callbacks (baseline) | {baseline:.1f} |")
    print(f"| phytrace-edge run --input ros | {ours:.1f} ({ours / baseline:.2f}×) |")


@dataclass(frozen=True)
class Row:
    """One process of the incident comparison: its label, its command's Python and
    input (``bare``: the rclpy node), its settings."""

    key: str
    label: str
    python: str
    input: str
    settings: dict[str, str] = field(default_factory=dict)

    def command(self, rates: str) -> list[str]:
        if self.input == "bare":
            return [self.python, __file__, "--child", "bare", "--rates", rates]
        return [self.python, "-m", "phytrace_edge", "run", "--input", self.input]


def incident_rows(rates: str, robot: str, with_dds: bool) -> list[Row]:
    off = {"INCIDENT_RECORDING": "false"}
    on = {"INCIDENT_RECORDING": "true"}
    rows = [
        Row("bare", "bare rclpy node, empty callbacks", sys.executable, "bare"),
        Row("ros-off", "`run --input ros`, INCIDENT_RECORDING=false", sys.executable, "ros", off),
        Row("ros-on", "`run --input ros`, window armed (30 s)", sys.executable, "ros", on),
    ]
    if rates == "demanding":  # a window long enough for the byte bound to cut it
        wide = {**on, "INCIDENT_BEFORE_S": "120"}
        rows.append(
            Row(
                "ros-on-120", "`run --input ros`, window armed (120 s)", sys.executable, "ros", wide
            )
        )
    if with_dds:
        rows += [
            Row("dds-off", "`run --input dds`, INCIDENT_RECORDING=false", robot, "dds", off),
            Row("dds-on", "`run --input dds`, window armed (30 s)", robot, "dds", on),
        ]
    return rows


def incident_cost(
    seconds: float, warm_up_s: float, rounds: int, robot: str, with_dds: bool
) -> dict[str, dict[str, list[Figures]]]:
    """Every row at each rate set, interleaved, ``rounds`` times (every other round in
    the reverse order, so that neither side always runs first)."""
    results: dict[str, dict[str, list[Figures]]] = {r: {} for r in WINDOW_RATES_HZ}
    env = domain_env()
    workdir = Path(tempfile.mkdtemp(prefix="bench-incident-"))
    try:
        for round_number in range(rounds):
            for rates in WINDOW_RATES_HZ:
                rows = incident_rows(rates, robot, with_dds)
                if round_number % 2:
                    rows.reverse()
                publisher = start_robot(robot, rates, env)
                try:
                    for row in rows:
                        queue = workdir / f"{rates}-{row.key}-{round_number}" / "queue.db"
                        queue.parent.mkdir()
                        run_env = (
                            env if row.input == "bare" else bridge_env(env, queue, **row.settings)
                        )
                        print(f"round {round_number + 1}, {rates}: {row.label}", flush=True)
                        figures = measure(
                            row.command(rates), run_env, seconds, warm_up_s, publisher.pid
                        )
                        print(f"  {json.dumps(figures.__dict__, default=str)}", flush=True)
                        results[rates].setdefault(row.key, []).append(figures)
                finally:
                    stop_robot(publisher)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return results


def mean(values: Sequence[float]) -> float:
    return statistics.fmean(values)


def incident_table(
    results: dict[str, dict[str, list[Figures]]], robot: str, with_dds: bool
) -> None:
    """The comparison as markdown: per rate set and row, the mean over the rounds."""
    print(
        "| rates | process | CPU, % of one core (each round) | × bare node | × today's bridge "
        "| RSS at end, MiB | peak RSS, MiB | window buffer: MiB, samples, dropped |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for rates, by_row in results.items():
        total = sum(WINDOW_RATES_HZ[rates].values())
        labels = {row.key: row.label for row in incident_rows(rates, robot, with_dds)}
        bare_cpu = mean([f.cpu_pct for f in by_row["bare"]])
        for key, runs in by_row.items():
            cpu = mean([f.cpu_pct for f in runs])
            each = ", ".join(f"{f.cpu_pct:.1f}" for f in runs)
            today_key = f"{key.split('-')[0]}-off"
            today = (
                f"{cpu / mean([f.cpu_pct for f in by_row[today_key]]):.2f}×"
                if today_key in by_row and key != today_key
                else ""
            )
            incidents = runs[-1].incidents
            buffer = (
                f"{mean([f.incidents.get('buffer_bytes', 0) for f in runs]) / MIB:.1f} of "
                f"{incidents.get('buffer_max_bytes', 0) / MIB:.0f}, "
                f"{mean([f.incidents.get('buffer_samples', 0) for f in runs]):.0f}, "
                f"{mean([f.incidents.get('samples_dropped', 0) for f in runs]):.0f}"
                if incidents.get("recording") or incidents.get("buffer_samples")
                else ""
            )
            print(
                f"| {rates}, {total} msg/s | {labels[key]} | {cpu:.1f} ({each}) "
                f"| {cpu / bare_cpu:.2f}× | {today} "
                f"| {mean([f.rss_mib for f in runs]):.1f} "
                f"| {mean([f.peak_mib for f in runs]):.1f} | {buffer} |"
            )
    loads = [
        x for by_row in results.values() for runs in by_row.values() for f in runs for x in f.load
    ]
    robots = [
        f.robot_cpu_pct for by_row in results.values() for runs in by_row.values() for f in runs
    ]
    print(
        f"\nmachine load (1 min) during the measurements: {min(loads):.2f} to {max(loads):.2f}; "
        f"the robot used {min(robots):.0f} to {max(robots):.0f} % of a core"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument("--incident", action="store_true", help="the armed window's cost")
    parser.add_argument("--rounds", type=int, default=2, help="--incident: times each row runs")
    parser.add_argument(
        "--warm-up", type=float, default=35.0, help="--incident: seconds before measuring"
    )
    parser.add_argument("--no-dds", action="store_true", help="--incident: no dds input rows")
    parser.add_argument("--robot-python", default="", help="a Python with cyclonedds")
    parser.add_argument("--json", type=Path, help="--incident: also write the figures here")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--rates", default="default", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        stop = threading.Event()
        threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
        {"publish": publish, "bare": bare}[args.child](stop, RATE_SETS[args.rates])
        return
    try:
        import rclpy  # noqa: F401 - only to say early that ROS 2 is not sourced
    except ImportError:
        sys.exit("rclpy is not importable: source ROS 2 first (see the docstring)")
    robot = robot_python(args.robot_python)
    if not args.incident:
        ros_cpu(args.seconds, robot)
        return
    with_dds = not args.no_dds
    results = incident_cost(args.seconds, args.warm_up, args.rounds, robot, with_dds)
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    r: {k: [f.__dict__ for f in v] for k, v in rows.items()}
                    for r, rows in results.items()
                },
                indent=1,
            )
        )
    incident_table(results, robot, with_dds)


if __name__ == "__main__":
    main()
