"""The image's ``ros`` input, for real: the bridge in the container (rclpy from the
``jazzy`` wheels, on Fast DDS) hears a real ROS 2 Jazzy robot node outside it, on the
host's network, on a private ROS domain confined to loopback, and delivers every value
of the ten topics to the stub on the host.

Fast DDS takes a participant in a container on the host's network for one on the same
host and delivers through shared memory, which the container must then share. Both
ways an operator can run the image beside Fast DDS nodes are tested
(docs/operations.md, "ROS 2 topics in a container"):

- ``ros``: ``--ipc host``, the robot's nodes and the container as one user (the
  image's, uid 10001: the robot here runs as that user);
- ``dds``: the ``dds`` input (Cyclone DDS, which Fast DDS reaches over UDP), the
  container as it comes, the robot as another user (root).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.container.conftest import Docker, docker
from tests.processes import wait_for
from tests.ros.known import KNOWN, carries_every_known_value, check_known_event
from tests.ros.rig import ROS_PYTHONS, Robot, private_domain, rclpy_missing, ros_env

pytestmark = pytest.mark.timeout(900)  # the first test of the session builds the image

IMAGE_UID = 10001
FAST_HEALTH = ("--health-interval", "2s", "--health-start-period", "2s", "--health-retries", "2")
SHARED_MEMORY = ("--ipc", "host")  # with the robot's nodes: Fast DDS to Fast DDS


@pytest.fixture
def robot_home() -> Iterator[Path]:
    """A folder the image's user owns, for the robot's ROS logs (tmp_path is root's)."""
    home = Path(tempfile.mkdtemp(prefix="phytrace-robot-"))
    os.chown(home, IMAGE_UID, IMAGE_UID)
    yield home
    shutil.rmtree(home, ignore_errors=True)


def runs_as(uid: int, env: dict[str, str]) -> bool:
    """Whether ``uid`` can run the Jazzy robot from this checkout (every folder above
    it must let that user through)."""
    probe = subprocess.run(
        [str(ROS_PYTHONS["jazzy"]), "-c", "import rclpy, tests.ros.fields"],
        capture_output=True,
        env=os.environ | env | {"PYTHONPATH": str(Path(__file__).parents[2])},
        user=uid,
        group=uid,
        timeout=120,
    )
    return probe.returncode == 0


@pytest.mark.parametrize("bridge_input", ["ros", "dds"])
def test_the_image_hears_a_real_robot_outside(
    containers: Docker, stub, tmp_path: Path, robot_home: Path, bridge_input: str
) -> None:
    if missing := rclpy_missing("jazzy"):
        if os.environ.get("CI"):  # in CI the real thing must run, never skip
            pytest.fail(missing)
        pytest.skip(missing)
    graph = ros_env(private_domain(), robot_home / "ros-logs")
    robot_env = graph | {"HOME": str(robot_home)}
    uid, user_flags = None, ()
    if bridge_input == "ros":
        if runs_as(IMAGE_UID, robot_env):
            uid = IMAGE_UID
        else:  # a checkout the image's user cannot read: both as root, as one user still
            print(f"\nuid {IMAGE_UID} cannot read this checkout: robot and container as root")
            user_flags = ("--user", "0")
    robot = Robot("jazzy", robot_env, tmp_path / "robot.log", uid)
    try:
        publishers = {t: robot.publisher(t, kind, qos) for t, (kind, qos, _) in KNOWN.items()}
        bridge = containers.run(
            "ros",
            "-v",
            f"{containers.volume('queue')}:/var/lib/phytrace-edge",
            *(SHARED_MEMORY if bridge_input == "ros" else ()),
            *user_flags,
            *FAST_HEALTH,
            env={
                "PHYCLOUD_ENDPOINT": stub.endpoint,
                "BRIDGE_INPUT": bridge_input,
                "SOURCE_ID": f"container-{bridge_input}",
                "SAMPLE_RATE_HZ": "5",
                "FLUSH_INTERVAL_S": "0.3",
                "HEALTH_EVENT_INTERVAL_S": "0",
                **{k: v for k, v in graph.items() if k != "ROS_LOG_DIR"},  # the image's own
            },
        )

        def every_value_arrived() -> dict | None:
            for topic, (_, _, fields) in KNOWN.items():  # a robot publishes again and again
                robot.publish(publishers[topic], fields)
            events = [e for e in stub.events() if e["event_type"] == "telemetry.periodic"]
            return next((e for e in reversed(events) if carries_every_known_value(e)), None)

        try:
            event = wait_for(every_value_arrived, 90, "an event with every topic's values", 0.3)
        except AssertionError:
            print(containers.logs(bridge)[-3000:], stub.stats(), stub.events()[-1:])
            print(containers.exec(bridge, "sh", "-c", "phytrace-edge status --json || true"))
            raise
        check_known_event(event)
        containers.wait_health(bridge, "healthy")
        assert containers.exec(bridge, "id", "-u") == ("0" if user_flags else str(IMAGE_UID))

        def topics() -> dict:  # status is the heartbeat's: seconds behind
            return json.loads(containers.exec(bridge, "phytrace-edge", "status", "--json"))[
                "topics"
            ]

        def heard() -> bool:  # the dds input counts writers once a second
            odom = topics()["/odom"]
            return odom["received"] > 0 and odom["publishers"] == 1

        wait_for(heard, 30, "/odom heard from its one publisher, in status")
        assert topics()["/battery_state"]["qos"] == "reliable, volatile"
        docker("stop", bridge, timeout=60)
        assert containers.state(bridge)["ExitCode"] == 0
    finally:
        robot.close()
