"""Shared fixtures."""

from __future__ import annotations

import importlib.util
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.flavours import FLAVOURS

HAVE_ROSBAGS = importlib.util.find_spec("rosbags") is not None


@pytest.fixture(autouse=True, scope="session")
def runtime_directory(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The bridges the tests start keep their live status (runtime/live_status.py) in
    a folder of the test run, as systemd's RuntimeDirectory would give them, not in
    the machine's /run; their processes inherit it."""
    folder = tmp_path_factory.mktemp("run")
    before = os.environ.get("RUNTIME_DIRECTORY")
    os.environ["RUNTIME_DIRECTORY"] = str(folder)
    yield folder
    if before is None:
        os.environ.pop("RUNTIME_DIRECTORY", None)
    else:
        os.environ["RUNTIME_DIRECTORY"] = before


@pytest.fixture(params=FLAVOURS)
def flavour(request: pytest.FixtureRequest) -> str:
    """Each handler test runs for rclpy, rosbags and DDS-like field types."""
    if request.param == "rosbags" and not HAVE_ROSBAGS:
        pytest.skip("rosbags is not installed (pip install .[bag])")
    return str(request.param)


class FakeClock:
    """A builder clock the test moves by hand."""

    def __init__(self, wall: float = 1_763_000_000.0) -> None:
        self.mono = 1000.0
        self.wall_s = wall

    def monotonic(self) -> float:
        return self.mono

    def wall(self) -> float:
        return self.wall_s

    def advance(self, seconds: float) -> None:
        self.mono += seconds
        self.wall_s += seconds


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


def non_finite_values(value: Any, path: str = "") -> list[str]:
    """Paths of every NaN, inf or None anywhere in ``value``."""
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in non_finite_values(v, f"{path}/{k}")]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in non_finite_values(v, f"{path}/{i}")]
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return [path]
    return []


@pytest.fixture
def stub_factory(tmp_path):
    """Start real stub processes; every one is killed at teardown."""
    from tests.processes import StubProcess

    started: list = []

    def start(*args: str, name: str = "stub", client: Any = None) -> StubProcess:
        stub = StubProcess(tmp_path / f"{name}.db", *args, client=client).start()
        started.append(stub)
        return stub

    yield start
    for stub in started:
        stub.stop()


@pytest.fixture
def stub(stub_factory):
    return stub_factory()


@pytest.fixture
def bridge_in_process(tmp_path, stub_factory):
    """``start(endpoint, wrap_transport=None, start=True, **env)``: a bridge service in
    this process (tests/bridge.py), started; every one stopped at teardown, before the
    stubs."""
    from tests.bridge import InProcessBridge, WrapTransport, bridge_settings

    started: list[InProcessBridge] = []

    def start(
        endpoint: str, wrap_transport: WrapTransport | None = None, start: bool = True, **env: str
    ) -> InProcessBridge:
        settings = bridge_settings(tmp_path, endpoint, **env)
        started.append(InProcessBridge(settings, wrap_transport, start))
        return started[-1]

    yield start
    for bridge in started:
        bridge.stop()


LOG_TAIL_LINES = 30


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """A failed test that ran real processes shows the end of their logs (``*.log``
    in its tmp_path): CI prints only the report, and the cause is often there."""
    report = yield
    tmp_path = getattr(item, "funcargs", {}).get("tmp_path")
    if report.failed and isinstance(tmp_path, Path) and tmp_path.is_dir():
        for log in sorted(tmp_path.glob("*.log")):
            lines = log.read_text(errors="replace").splitlines()[-LOG_TAIL_LINES:]
            report.sections.append((f"last lines of {log.name}", "\n".join(lines)))
    return report
