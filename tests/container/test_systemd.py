"""The systemd unit under a real systemd (PID 1 of a container on the stand-in base),
installed by the steps of docs/operations.md as written (two substitutions: the package
comes from this checkout, and the editor step becomes a sed), so the docs cannot drift.
Then: READY, the watchdog on a frozen process, a restart after kill -9, a clean stop,
the state directory's modes, the documented status command, journal priorities, and
`systemctl reload` (SIGHUP: a line, and the bridge lives on)."""

from __future__ import annotations

import io
import re
import subprocess
import tarfile
import uuid
from collections.abc import Iterator

import pytest

from tests.container import standin
from tests.container.conftest import docker, docker_usable
from tests.processes import ROOT, wait_for

pytestmark = pytest.mark.timeout(900)
DOCS = ROOT / "docs" / "operations.md"
# how systemd boots as PID 1 in a container on these machines (measured here)
BOOT_FLAGS = (
    "--cap-add", "ALL", "--cap-drop", "SYS_RESOURCE", "--cap-drop", "SYS_MODULE",
    "--security-opt", "seccomp=unconfined", "--security-opt", "apparmor=unconfined",
    "-v", "/sys/fs/cgroup:/sys/fs/cgroup:rw", "--cgroupns", "host",
    "--tmpfs", "/run", "--tmpfs", "/run/lock", "-e", "container=docker",
    "--network", "host", "--stop-signal", "SIGRTMIN+3",
)  # fmt: skip
ENV_FILE = "/etc/phytrace-edge/phytrace-edge.env"


def install_steps(endpoint: str) -> list[str]:
    """The install block of docs/operations.md, one command per line, with the two
    substitutions the test needs."""
    section = DOCS.read_text().split("## Install on a robot (systemd)", 1)[1]
    block = section.split("```sh\n", 1)[1].split("```", 1)[0]
    commands = [line.split("  #")[0].strip() for line in block.splitlines()]
    commands = [c for c in commands if c and not c.startswith("#")]
    out = []
    for command in commands:
        if "pip install 'phytrace-edge[dds]'" in command:
            command = command.replace("'phytrace-edge[dds]'", "'/srv/src[dds]'")
        elif command.startswith("sudoedit "):
            settings = {"PHYCLOUD_ENDPOINT": endpoint, "BRIDGE_INPUT": "sim"}
            command = " && ".join(
                f"sudo sed -i 's|^{key}=.*|{key}={value}|' {ENV_FILE}"
                for key, value in settings.items()
            )
        out.append(command)
    return out


def copy_checkout(container: str) -> None:
    """What the install steps use of this checkout (no virtual environments), to
    /srv/src in the container."""
    archive = io.BytesIO()
    with tarfile.open(fileobj=archive, mode="w") as tar:
        for part in ("pyproject.toml", "README.md", "phytrace_edge", "migrations", "systemd"):
            tar.add(
                ROOT / part,
                arcname=f"src/{part}",
                filter=lambda info: None if "__pycache__" in info.name else info,
            )
    subprocess.run(
        ["docker", "cp", "-", f"{container}:/srv"],
        input=archive.getvalue(),
        check=True,
        timeout=120,
    )


class Machine:
    """A container booted with systemd as PID 1."""

    def __init__(self, name: str) -> None:
        self.name = name

    def sh(self, command: str, check: bool = True, timeout: float = 300) -> str:
        """``command`` in the checkout's copy, as the docs' steps expect."""
        result = docker(
            "exec", "-w", "/srv/src", self.name, "bash", "-c", command, timeout=timeout, check=False
        )
        if check:
            assert result.returncode == 0, f"{command}\n{result.stdout}\n{result.stderr}"
        return result.stdout.strip()

    def show(self, *properties: str) -> dict[str, str]:
        text = self.sh(f"systemctl show phytrace-edge -p {','.join(properties)}")
        return dict(line.split("=", 1) for line in text.splitlines())


@pytest.fixture
def machine() -> Iterator[Machine]:
    why = docker_usable()
    if why:
        pytest.skip(f"Docker cannot run here: {why}")
    base = standin.build()
    name = f"phytrace-systemd-{uuid.uuid4().hex[:8]}"
    docker("run", "-d", "--name", name, *BOOT_FLAGS, base, "/lib/systemd/systemd")
    try:
        booted = Machine(name)
        wait_for(
            lambda: (
                docker("exec", name, "test", "-S", "/run/systemd/private", check=False).returncode
                == 0
            ),
            60,
            "systemd to boot",
        )
        docker("exec", name, "systemctl", "is-system-running", "--wait", timeout=120, check=False)
        copy_checkout(name)
        yield booted
    finally:
        docker("rm", "-f", "-v", name, check=False)


def test_the_unit_installed_as_documented_runs_under_real_systemd(machine: Machine, stub) -> None:
    for command in install_steps(stub.endpoint):
        try:
            machine.sh(command)
        except AssertionError as failed:  # say why: the service's own last words
            journal = machine.sh("journalctl -u phytrace-edge -n 40 --no-pager", check=False)
            raise AssertionError(f"{failed}\nthe service's journal:\n{journal}") from None
    # READY: Type=notify is active only once the bridge said so
    assert machine.sh("systemctl is-active phytrace-edge") == "active"
    assert "queued" in machine.show("StatusText")["StatusText"]
    wait_for(lambda: stub.stats()["unique"] > 10, 60, "events from the service")
    # the documented status command, as the service user
    status = machine.sh(f"sudo -u phytrace phytrace-edge status --env-file {ENV_FILE}")
    assert status.startswith("phytrace-edge status: HEALTHY")
    # the state directory and the queue's files: the service user's, private
    modes = machine.sh("stat -c '%a %U' /var/lib/phytrace-edge /var/lib/phytrace-edge/queue.db")
    assert modes.splitlines() == ["700 phytrace", "600 phytrace"]

    # kill -9: restarted by Restart=on-failure
    first = machine.show("MainPID")["MainPID"]
    machine.sh("systemctl kill -s KILL phytrace-edge")

    def restarted() -> bool:
        now = machine.show("MainPID", "ActiveState")
        return now["ActiveState"] == "active" and now["MainPID"] not in ("0", first)

    wait_for(restarted, 60, "a restart after kill -9")
    # a frozen process: the watchdog (WatchdogSec=30) kills it, and it is restarted
    frozen = machine.show("MainPID")["MainPID"]
    restarts = int(machine.show("NRestarts")["NRestarts"])
    machine.sh(f"kill -STOP {frozen}")
    wait_for(
        lambda: (
            int(machine.show("NRestarts")["NRestarts"]) > restarts
            and machine.show("ActiveState")["ActiveState"] == "active"
        ),
        90,
        "the watchdog to restart a frozen bridge",
    )
    assert "watchdog" in machine.sh("journalctl -u phytrace-edge --no-pager").lower()

    # journal priorities: PhyCloud goes away, the bridge warns, `-p warning` shows it
    stub.kill()
    wait_for(
        lambda: (
            "send failed" in machine.sh("journalctl -u phytrace-edge -p warning --no-pager -o cat")
        ),
        60,
        "a WARNING in the journal at its priority",
    )
    warnings = machine.sh("journalctl -u phytrace-edge -p warning --no-pager -o cat")
    assert "subscribed to" not in warnings  # INFO lines stay out of -p warning
    assert not re.search(r"^<\d>", warnings, re.MULTILINE)  # journald stripped the prefix

    # `systemctl reload` (ExecReload=): SIGHUP, one line, and the bridge lives on
    pid = machine.show("MainPID")["MainPID"]
    machine.sh("systemctl reload phytrace-edge")
    wait_for(
        lambda: (
            "restart the service to change it"
            in machine.sh("journalctl -u phytrace-edge --no-pager -o cat")
        ),
        30,
        "the reload's line",
    )
    assert machine.show("MainPID", "ActiveState") == {"MainPID": pid, "ActiveState": "active"}

    # a clean stop: exit 0, nothing lost from the queue's point of view
    machine.sh("systemctl stop phytrace-edge")
    stopped = machine.show("Result", "ExecMainStatus", "ActiveState")
    assert stopped == {"Result": "success", "ExecMainStatus": "0", "ActiveState": "inactive"}
