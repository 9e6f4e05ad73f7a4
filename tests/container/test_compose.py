"""`docker-compose --profile dev up` with the shipped compose.yaml (Debian's compose
v1.29; the v2 plugin reads the same file, validated against the Compose Specification
in tests/integration/test_deployment.py): a healthy bridge and a healthy stub, and the
bridge's events at the stub. Only the image (the one built on the stand-in) and the
health checks' intervals are overridden."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import uuid
from pathlib import Path

import httpx
import pytest

from tests.container.conftest import docker
from tests.processes import ROOT, wait_for

pytestmark = pytest.mark.timeout(900)
STUB_PORT = 8000  # the compose file's


def port_free(port: int) -> bool:
    with socket.socket() as sock:
        return sock.connect_ex(("127.0.0.1", port)) != 0


def test_the_dev_profile_brings_up_a_healthy_bridge_and_stub(image: str, tmp_path: Path) -> None:
    compose = shutil.which("docker-compose")
    if compose is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    if not port_free(STUB_PORT):
        pytest.skip(f"port {STUB_PORT}, the compose file's stub port, is in use here")
    override = tmp_path / "compose.test.yaml"
    fast = {"interval": "2s", "start_period": "2s", "retries": 2}
    override.write_text(
        json.dumps(
            {
                "services": {
                    "phytrace-bridge": {"image": image, "healthcheck": fast},
                    "phycloud-stub": {"image": image, "healthcheck": fast},
                }
            }
        )
    )
    project = f"phytrace-test-{uuid.uuid4().hex[:8]}"
    command = [compose, "-p", project, "-f", str(ROOT / "compose.yaml"), "-f", str(override)]
    env = {
        **os.environ,
        "PHYCLOUD_ENDPOINT": f"http://127.0.0.1:{STUB_PORT}/api/v1",
        "BRIDGE_INPUT": "sim",
        "SOURCE_ID": "compose-robot-1",
    }

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [*command, *args], env=env, capture_output=True, text=True, timeout=300
        )

    try:
        up = run("--profile", "dev", "up", "-d", "--no-build")
        assert up.returncode == 0, up.stderr
        names = {
            service: f"{project}_{service}_1" for service in ("phytrace-bridge", "phycloud-stub")
        }

        def health(name: str) -> str:
            state = docker("inspect", "--format", "{{json .State}}", name).stdout
            return (json.loads(state).get("Health") or {}).get("Status", "")

        for name in names.values():
            wait_for(lambda name=name: health(name) == "healthy", 120, f"{name} healthy")

        def events_at_stub() -> int:
            stats = httpx.get(f"http://127.0.0.1:{STUB_PORT}/api/v1/stats", timeout=10).json()
            return int(stats["by_source"].get("compose-robot-1", 0))

        wait_for(lambda: events_at_stub() > 10, 60, "the bridge's events at the stub")
    finally:
        down = run("--profile", "dev", "down", "-v", "--remove-orphans")
        assert down.returncode == 0, down.stderr
    leftovers = docker("ps", "-a", "--filter", f"name={project}", "--format", "{{.Names}}").stdout
    assert leftovers.strip() == ""
