"""Real Docker: the project's image built on a stand-in base (``standin.py``), run with
``--network host``; every container and volume a test makes is removed after it.
Skipped, saying why, where Docker cannot run (not root, no daemon)."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.container import standin
from tests.processes import ROOT, wait_for


def docker(
    *args: str, timeout: float = 120, check: bool = True
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["docker", *args], capture_output=True, text=True, timeout=timeout, check=check
    )


def docker_usable() -> str | None:
    """Why Docker cannot be used here, or None."""
    if shutil.which("docker") is None:
        return "no docker command (apt-get install docker.io)"
    if os.geteuid() != 0:
        return "not root: the tests start containers with host networking"
    if docker("version", "--format", "{{.Server.Version}}", check=False, timeout=30).returncode:
        return "no Docker daemon (start dockerd as root)"
    return None


def build_image(dockerfile: str, name: str, *build_args: str) -> str:
    """``dockerfile`` built on the stand-in base, tagged by that base's key; skipped,
    saying why, where Docker cannot run."""
    why = docker_usable()
    if why:
        pytest.skip(f"Docker cannot run here: {why}")
    base = standin.build()
    tag = f"{name}:test-{standin.content_key()}"
    started = time.monotonic()
    args = [item for arg in (f"BASE_IMAGE={base}", *build_args) for item in ("--build-arg", arg)]
    build = docker(
        "build",
        "--network",
        "host",
        "-f",
        str(ROOT / dockerfile),
        *args,
        "-t",
        tag,
        str(ROOT),
        timeout=1200,
        check=False,
    )
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    size = int(docker("image", "inspect", "--format", "{{.Size}}", tag).stdout)
    print(f"\ndocker build {dockerfile}: {time.monotonic() - started:.1f} s, {size / 1e6:.0f} MB")
    return tag


@pytest.fixture(scope="session")
def image() -> str:
    """The project's image (Dockerfile: the wheels) on the stand-in base."""
    return build_image("Dockerfile", "phytrace-edge")


class Docker:
    """Containers and volumes of one test, all removed at its end."""

    def __init__(self, image: str) -> None:
        self.image = image
        self.prefix = f"phytrace-test-{uuid.uuid4().hex[:8]}"
        self.containers: list[str] = []
        self.volumes: list[str] = []

    def volume(self, name: str) -> str:
        full = f"{self.prefix}-{name}"
        docker("volume", "create", full)
        self.volumes.append(full)
        return full

    def run(self, name: str, *args: str, env: dict[str, str], command: tuple[str, ...] = ()) -> str:
        """Start a detached container of the image on the host's network."""
        full = f"{self.prefix}-{name}"
        flags = [item for key, value in env.items() for item in ("-e", f"{key}={value}")]
        docker(
            "run", "-d", "--name", full, "--network", "host", *flags, *args, self.image, *command
        )
        self.containers.append(full)
        return full

    def state(self, container: str) -> dict[str, Any]:
        import json

        return json.loads(docker("inspect", "--format", "{{json .State}}", container).stdout)

    def health(self, container: str) -> str | None:
        return (self.state(container).get("Health") or {}).get("Status")

    def logs(self, container: str) -> str:
        result = docker("logs", container, check=False)
        return result.stdout + result.stderr

    def exec(self, container: str, *command: str) -> str:
        return docker("exec", container, *command).stdout.strip()

    def wait_health(self, container: str, wanted: str, timeout: float = 90) -> None:
        wait_for(lambda: self.health(container) == wanted, timeout, f"{container} {wanted}")

    def cleanup(self) -> None:
        for container in self.containers:
            docker("rm", "-f", "-v", container, check=False)
        for volume in self.volumes:
            docker("volume", "rm", "-f", volume, check=False)


@pytest.fixture
def containers(image: str) -> Iterator[Docker]:
    made = Docker(image)
    try:
        yield made
    finally:
        made.cleanup()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    here = Path(__file__).parent
    for item in items:
        if here in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.container)
