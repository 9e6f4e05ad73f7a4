"""Ingest benchmark: handler cost per message, bag replay throughput, CPU of a realistic
robot load.

    .venv/bin/python tools/bench_ingest.py                   # about 3 minutes
    .venv/bin/python tools/bench_ingest.py --cpu-seconds 10  # quick

1. Per topic, median microseconds per message of Cyclone DDS deserialisation alone (what
   any DDS reader pays: the baseline) and of deserialisation plus the bridge's handler;
   then the handler alone on the message an rclpy subscription receives (the simulated
   robot's, through the mock rclpy), against the goal per topic.
2. Replay of a large bag recorded from the simulator: bare rosbags reading and
   deserialising (the baseline) against the bridge's replay (handlers, builder, events).
3. A realistic robot (odom 50 Hz, imu 200 Hz, joint_states 100 Hz, scan 15 Hz with 1081
   ranges, gps 10 Hz, cmd_vel 20 Hz, battery 1 Hz, diagnostics 1 Hz) published over DDS
   by another process for a minute; CPU of `phytrace-edge run --bridge-input dds` at
   SAMPLE_RATE_HZ=10 shipping to the stub, against a bare Cyclone reader of the same
   topics (the baseline), each as a percentage of one core.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from phytrace_edge.ingest.sources import dds_types as t  # noqa: E402
from phytrace_edge.ingest.topics import TOPIC_BY_NAME  # noqa: E402

RATES_HZ = {
    "/odom": 50,
    "/imu/data": 200,
    "/joint_states": 100,
    "/scan": 15,
    "/gps/fix": 10,
    "/cmd_vel": 20,
    "/battery_state": 1,
    "/diagnostics": 1,
}


def header(frame: str) -> t.Header_:
    return t.Header_(stamp=t.Time_(sec=1_763_000_000, nanosec=1), frame_id=frame)


def samples() -> dict[str, object]:
    """One realistic message per topic, as the DDS IDL types."""
    odom = t.Odometry_(header=header("odom"), child_frame_id="base_link")
    odom.pose.pose = t.Pose_(
        position=t.Point_(x=12.3, y=4.5), orientation=t.Quaternion_(z=0.38, w=0.92)
    )
    odom.twist.twist = t.Twist_(linear=t.Vector3_(x=0.8), angular=t.Vector3_(z=0.1))
    ranges = [2.0 + math.sin(i / 50) if i % 40 else math.inf for i in range(1081)]
    return {
        "/odom": odom,
        "/imu/data": t.Imu_(
            header=header("imu"),
            orientation=t.Quaternion_(z=0.38, w=0.92),
            angular_velocity=t.Vector3_(z=0.1),
            linear_acceleration=t.Vector3_(z=9.81),
        ),
        "/joint_states": t.JointState_(
            header=header("base"),
            name=["left", "right"],
            position=[1.0, 2.0],
            velocity=[0.5, 0.5],
            effort=[],
        ),
        "/scan": t.LaserScan_(
            header=header("lidar"),
            angle_min=-2.35,
            angle_max=2.35,
            angle_increment=4.7 / 1080,
            range_min=0.05,
            range_max=30.0,
            ranges=ranges,
        ),
        "/gps/fix": t.NavSatFix_(
            header=header("gps"),
            status=t.NavSatStatus_(status=0),
            latitude=41.87,
            longitude=-87.62,
            altitude=180.0,
        ),
        "/cmd_vel": t.Twist_(linear=t.Vector3_(x=1.0), angular=t.Vector3_(z=0.1)),
        "/battery_state": t.BatteryState_(
            header=header("bat"),
            voltage=24.1,
            percentage=0.8,
            power_supply_status=2,
            cell_voltage=[4.0] * 6,
        ),
        "/diagnostics": t.DiagnosticArray_(
            header=header(""),
            status=[
                t.DiagnosticStatus_(level=1, name=f"n{i}", message="m", hardware_id="h")
                for i in range(8)
            ],
        ),
        "/goal_pose": t.PoseStamped_(header=header("map"), pose=t.Pose_(position=t.Point_(x=4.0))),
        "/delivery/status": t.String_(data='{"order_id": "o-1", "state": "in_transit"}'),
    }


def median_us(work, repeats: int = 7, inner: int = 200) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        for _ in range(inner):
            work()
        times.append((time.perf_counter() - started) / inner * 1e6)
    return statistics.median(times)


# Handler cost per message the design aims for (issue 13); others have none set.
GOALS_US = {
    "/odom": 20.0,
    "/imu/data": 20.0,
    "/battery_state": 20.0,
    "/diagnostics": 20.0,
    "/scan": 60.0,
}


def handler_table() -> list[tuple[str, float, float]]:
    rows = []
    for topic, sample in samples().items():
        kind, data = type(sample), sample.serialize()
        handler = TOPIC_BY_NAME[topic].handler
        alone = median_us(lambda k=kind, d=data: k.deserialize(d))
        full = median_us(lambda k=kind, d=data, h=handler: h(k.deserialize(d)))
        rows.append((topic, alone, full))
    return rows


def rclpy_handler_table() -> list[tuple[str, float]]:
    """The handler alone on the last message of each topic of 10 s of the simulated
    robot, as an rclpy subscription receives it (field types of real rclpy)."""
    from phytrace_edge.sim.recorder import simulate

    latest = {topic: msg for topic, _, msg in simulate(10.0)}
    rows = []
    for topic, msg in sorted(latest.items()):
        if topic not in TOPIC_BY_NAME:  # the robot's extra topic (TOPICS_EXTRA): no handler
            continue
        handler = TOPIC_BY_NAME[topic].handler
        rows.append((topic, median_us(lambda h=handler, m=msg: h(m))))
    return rows


def replay_table(workdir: Path, seconds: int) -> tuple[int, float, float]:
    import threading as th

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from phytrace_edge.config import load_settings
    from phytrace_edge.ingest.sources.registry import create_source
    from phytrace_edge.runtime import options, wiring
    from phytrace_edge.sim.recorder import record_simulation

    bag = workdir / "large"
    counts = record_simulation(bag, seconds, storage="mcap", custom_topic=False)
    messages = sum(counts.values())

    started = time.perf_counter()
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
    bare = messages / (time.perf_counter() - started)

    # the bridge's own pipeline for a bag, as fast as it goes; events built, not queued
    settings = load_settings(
        env={"BRIDGE_INPUT": f"bag:{bag}", "REPLAY_RATE": "0", "STALE_AFTER_S": "5"}
    ).settings
    source = create_source(options.source_options(settings, {}))
    pipeline = wiring.build_pipeline(settings, source, lambda built: None)
    started = time.perf_counter()
    pipeline.open()
    pipeline.ingest(th.Event(), lambda: None)
    ours = messages / (time.perf_counter() - started)
    pipeline.source.stop()
    return messages, bare, ours


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def publish_load(stop: threading.Event, rates: dict[str, int] = RATES_HZ) -> None:
    """The realistic robot: each topic at its rate, from a thread per topic."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
    from phytrace_edge.ingest.sources.dds_env import domain_settings

    domain_id, localhost = domain_settings(os.environ)
    _domain = Domain(domain_id, domain_config(localhost_only=True)) if localhost else None
    participant = DomainParticipant(domain_id)
    qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
    threads = []
    for topic, rate in rates.items():
        sample = samples()[topic]
        writer = DataWriter(
            participant, Topic(participant, dds_topic_name(topic), type(sample)), qos=qos
        )

        def loop(w=writer, s=sample, period=1.0 / rate) -> None:
            next_at = time.monotonic()
            while not stop.wait(max(0.0, next_at - time.monotonic())):
                w.write(s)
                next_at += period

        threads.append(threading.Thread(target=loop, daemon=True))
    for thread in threads:
        thread.start()
    stop.wait()


def bare_reader(stop: threading.Event) -> None:
    """The baseline: a Cyclone reader per topic that takes samples and does nothing."""
    from cyclonedds.core import Listener, Policy, Qos
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
    from phytrace_edge.ingest.sources.dds_env import domain_settings

    domain_id, localhost = domain_settings(os.environ)
    _domain = Domain(domain_id, domain_config(localhost_only=True)) if localhost else None
    participant = DomainParticipant(domain_id)
    qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100))
    readers = [
        DataReader(
            participant,
            Topic(participant, dds_topic_name(topic), type(sample)),
            qos=qos,
            listener=Listener(on_data_available=lambda r: r.take(N=100)),
        )
        for topic, sample in samples().items()
    ]
    stop.wait()
    del readers


def child(role: str) -> None:
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    {"publish": publish_load, "bare": bare_reader}[role](stop)


def cpu_table(workdir: Path, seconds: float) -> list[tuple[str, float]]:
    from tests.processes import StubProcess, python_env

    env = python_env(ROS_DOMAIN_ID="213", ROS_LOCALHOST_ONLY="1")
    stub = StubProcess(workdir / "stub.db").start()
    publisher = subprocess.Popen(
        [sys.executable, __file__, "--child", "publish"], stdin=subprocess.PIPE, env=env
    )
    results = []
    try:
        for name, command, extra in (
            ("bare Cyclone reader (baseline)", [sys.executable, __file__, "--child", "bare"], {}),
            (
                "phytrace-edge run --bridge-input dds",
                [sys.executable, "-m", "phytrace_edge", "run"],
                {
                    "BRIDGE_INPUT": "dds",
                    "SAMPLE_RATE_HZ": "10",
                    "PHYCLOUD_ENDPOINT": stub.endpoint,
                    "QUEUE_PATH": str(workdir / "queue.db"),
                    "LOG_LEVEL": "WARNING",
                },
            ),
        ):
            process = subprocess.Popen(command, stdin=subprocess.PIPE, env={**env, **extra})
            time.sleep(5)  # warm up: discovery, imports, first events
            before, started = cpu_seconds(process.pid), time.monotonic()
            time.sleep(seconds)
            used = cpu_seconds(process.pid) - before
            results.append((name, 100 * used / (time.monotonic() - started)))
            process.terminate()
            process.wait(timeout=30)
        results.append(("events at the stub", float(stub.stats()["unique"])))
    finally:
        publisher.stdin.close()
        publisher.wait(timeout=30)
        stub.stop()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cpu-seconds", type=float, default=60)
    parser.add_argument("--bag-seconds", type=int, default=1200)
    parser.add_argument("--handlers-only", action="store_true", help="only the handler tables")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child)
        return
    workdir = Path(tempfile.mkdtemp(prefix="bench-ingest-"))
    try:
        print(
            "| topic | DDS deserialise only (µs/msg, baseline) | deserialise + handler (µs/msg) "
            "| ratio |\n|---|---|---|---|"
        )
        for topic, alone, full in handler_table():
            print(f"| {topic} | {alone:.1f} | {full:.1f} | {full / alone:.2f}× |")
        print("\n| topic | handler alone, rclpy message (µs/msg) | goal (µs) |\n|---|---|---|")
        for topic, cost in rclpy_handler_table():
            goal = GOALS_US.get(topic)
            verdict = "" if goal is None else f"< {goal:.0f} ({'met' if cost < goal else 'missed'})"
            print(f"| {topic} | {cost:.1f} | {verdict} |")
        if args.handlers_only:
            return
        messages, bare, ours = replay_table(workdir, args.bag_seconds)
        print(
            f"\n| bag replay ({messages:,} messages, mcap) | messages/s |\n|---|---|\n"
            f"| rosbags read + deserialise (baseline) | {bare:,.0f} |\n"
            f"| phytrace-edge replay at rate 0 | {ours:,.0f} ({ours / bare:.2f}×) |"
        )
        rows = cpu_table(workdir, args.cpu_seconds)
        print(
            f"\n| realistic robot over DDS, {args.cpu_seconds:.0f} s | CPU, % of one core |"
            "\n|---|---|"
        )
        for name, value in rows:
            print(
                f"| {name} | {value:.1f} |" if "events" not in name else f"| {name} | {value:.0f} |"
            )
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
