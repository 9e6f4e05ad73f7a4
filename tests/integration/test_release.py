"""The release as a user gets it: ``python -m build`` makes an sdist and, from it, a
wheel; the wheel holds the package data (queue migrations, launch files and
parameters, the UDM schema, the queue's compression dictionary, the stub's page); and
installed into a clean venv, run from a folder with no source tree, it runs the demo's
job - the simulated robot, the bridge, the stub - and ``status`` says HEALTHY."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tarfile
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.processes import ROOT, wait_for

pytestmark = pytest.mark.timeout(900)


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    built = subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert built.returncode == 0, built.stderr[-2000:]
    return out


def only(folder: Path, pattern: str) -> Path:
    found = list(folder.glob(pattern))
    assert len(found) == 1, found
    return found[0]


def test_the_wheel_holds_the_package_data(dist: Path) -> None:
    names = set(zipfile.ZipFile(only(dist, "*.whl")).namelist())
    expected = {
        *(
            f"phytrace_edge/queue/storage/migrations/{m.name}"
            for m in (ROOT / "migrations").glob("*.sql")
        ),
        *(
            str(p.relative_to(ROOT))
            for pattern in (
                "launch/*",
                "udm/*.json",
                "queue/encoding/*.zdict",
                "stub/*.html",
                "py.typed",
            )
            for p in (ROOT / "phytrace_edge").glob(pattern)
            if p.is_file() and "__pycache__" not in p.parts
        ),
    }
    assert len(expected) > 12  # the globs found the data, not nothing
    assert expected <= names, sorted(expected - names)
    assert not [n for n in names if n.startswith(("tests/", "tools/")) or "__pycache__" in n]


def test_the_sdist_has_what_builds_the_package_and_nothing_local(dist: Path) -> None:
    with tarfile.open(only(dist, "*.tar.gz")) as sdist:
        names = {name.split("/", 1)[1] for name in sdist.getnames() if "/" in name}
    assert {"pyproject.toml", "README.md", "package.xml", "phytrace_edge/__init__.py"} <= names
    assert {f"migrations/{m.name}" for m in (ROOT / "migrations").glob("*.sql")} <= names
    local = [n for n in names if n.startswith((".venv", ".demo")) or "node_modules" in n]
    assert local == []


@pytest.fixture(scope="module")
def installed(dist: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A clean venv with the wheel and its stub extra: its bin folder."""
    venv = tmp_path_factory.mktemp("release") / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    wheel = only(dist, "*.whl")
    done = subprocess.run(
        [str(venv / "bin" / "pip"), "install", "-q", f"{wheel}[stub]"],
        capture_output=True,
        text=True,
        timeout=600,
        env=clean_env(),
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return venv / "bin"


def clean_env(**extra: str) -> dict[str, str]:
    """The environment without this checkout on the path or the bridge's settings."""
    kept = {
        k: v
        for k, v in os.environ.items()
        if k != "PYTHONPATH"
        and not k.startswith(("PHYCLOUD_", "QUEUE_"))
        and not k.lower().endswith("_proxy")
    }
    return {**kept, **extra}


@pytest.fixture
def processes() -> Iterator[list[subprocess.Popen[str]]]:
    started: list[subprocess.Popen[str]] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=10)


def test_the_installed_wheel_runs_the_bridge_and_status(
    installed: Path, tmp_path: Path, processes: list[subprocess.Popen[str]]
) -> None:
    cli = str(installed / "phytrace-edge")
    where = subprocess.run(
        [str(installed / "python"), "-c", "import phytrace_edge; print(phytrace_edge.__file__)"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=clean_env(),
    )
    assert where.stdout.startswith(str(installed.parent)), where  # the wheel, not ROOT
    stub = subprocess.Popen(
        [cli, "stub", "--host", "127.0.0.1", "--port", "0", "--db", str(tmp_path / "stub.db")],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=tmp_path,
        env=clean_env(),
    )
    processes.append(stub)
    match = re.search(r"127\.0\.0\.1:(\d+)", stub.stdout.readline())  # type: ignore[union-attr]
    assert match, "the stub did not start"
    endpoint = f"http://127.0.0.1:{match.group(1)}/api/v1"
    settings = clean_env(
        PHYCLOUD_ENDPOINT=endpoint,
        QUEUE_PATH=str(tmp_path / "queue.db"),
        BRIDGE_INPUT="sim",
        FLUSH_INTERVAL_S="0.3",
    )
    with (tmp_path / "bridge.log").open("w") as log:
        bridge = subprocess.Popen(
            [cli, "run"], stdout=log, stderr=log, text=True, cwd=tmp_path, env=settings
        )
    processes.append(bridge)

    def received() -> int:
        try:
            return int(httpx.get(f"{endpoint}/stats", timeout=5).json()["unique"])
        except httpx.HTTPError:
            return 0

    wait_for(lambda: received() >= 10, 90, "events from the installed bridge")
    status = subprocess.run(
        [cli, "status", "--json"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=settings,
    )
    document = json.loads(status.stdout)
    assert status.returncode == 0 and document["healthy"], document["problems"]
    bridge.send_signal(signal.SIGTERM)
    assert bridge.wait(timeout=60) == 0
