"""The `ros` input's CPU beside a bare rclpy node with empty callbacks, side by side in
one run, at a realistic robot's load (needs ROS 2 sourced: rclpy and the message
packages; the robot is a Cyclone DDS publisher speaking ROS 2's wire types).

    source /opt/ros/jazzy/setup.bash && export RMW_IMPLEMENTATION=rmw_cyclonedds_cpp
    .venv/bin/python tools/bench_ros_cpu.py --seconds 60

Prints a table: % of one core for each, and the ratio (goal: <= 1.0).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench_ingest import cpu_seconds, publish_load  # tools/, beside this file

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


def publish(stop: threading.Event) -> None:
    """The robot: each topic at its rate, Cyclone DDS with ROS 2's names and types."""
    publish_load(stop, RATES_HZ)


def bare(stop: threading.Event) -> None:
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
    for topic, (module, name) in TYPES.items():
        message = getattr(importlib.import_module(module), name)
        node.create_subscription(message, topic, lambda msg: None, qos_profile_sensor_data)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.1)
    rclpy.try_shutdown()


def measure(command: list[str], env: dict[str, str], seconds: float) -> float:
    """% of one core a process uses over ``seconds``, after its warm-up."""
    process = subprocess.Popen(command, stdin=subprocess.PIPE, env=env)
    try:
        time.sleep(WARM_UP_S)  # a benchmark's pacing: imports, discovery, first events
        before, started = cpu_seconds(process.pid), time.monotonic()
        time.sleep(seconds)
        return 100 * (cpu_seconds(process.pid) - before) / (time.monotonic() - started)
    finally:
        if "QUEUE_PATH" in env:  # the bridge: say what it heard, or the figure means nothing
            print(heard(env), flush=True)
        process.terminate()
        process.wait(timeout=30)


def heard(env: dict[str, str]) -> str:
    """The messages the running bridge received per topic, from its status."""
    status = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "status", "--json"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    topics = json.loads(status.stdout).get("topics", {}) if status.stdout else {}
    counts = ", ".join(f"{t} {topics[t].get('received', 0)}" for t in RATES_HZ if t in topics)
    return f"the bridge heard: {counts or 'nothing'}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        stop = threading.Event()
        threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
        {"publish": publish, "bare": bare}[args.child](stop)
        return
    try:
        import rclpy  # noqa: F401 - only to say early that ROS 2 is not sourced
    except ImportError:
        sys.exit("rclpy is not importable: source ROS 2 first (see the docstring)")
    workdir = Path(tempfile.mkdtemp(prefix="bench-ros-"))
    env = {  # a private domain, its discovery confined to loopback
        **os.environ,
        "ROS_DOMAIN_ID": "217",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOCALHOST_ONLY": "1",
        "PYTHONUNBUFFERED": "1",
    }
    robot = subprocess.Popen(
        [sys.executable, __file__, "--child", "publish"], stdin=subprocess.PIPE, env=env
    )
    try:
        baseline = measure([sys.executable, __file__, "--child", "bare"], env, args.seconds)
        ours_env = {
            **env,
            "PHYCLOUD_ENDPOINT": "http://127.0.0.1:9/api/v1",  # nobody: sends fail fast
            "QUEUE_PATH": str(workdir / "queue.db"),
            "SAMPLE_RATE_HZ": "5",
            "HEALTH_EVENT_INTERVAL_S": "0",
            "LOG_LEVEL": "ERROR",
        }
        command = [sys.executable, "-m", "phytrace_edge", "run", "--input", "ros"]
        ours = measure(command, ours_env, args.seconds)
    finally:
        robot.stdin.close()
        robot.wait(timeout=30)
        shutil.rmtree(workdir, ignore_errors=True)
    load = sum(RATES_HZ.values())
    print(f"| `ros` input, {load} messages/s, {args.seconds:.0f} s | CPU, % of one core |")
    print("|---|---|")
    print(f"| bare rclpy node, empty callbacks (baseline) | {baseline:.1f} |")
    print(f"| phytrace-edge run --input ros | {ours:.1f} ({ours / baseline:.2f}×) |")


if __name__ == "__main__":
    main()
