"""The ``rig`` fixture: each test of this folder on the mock and on real rclpy of
each ROS 2 distribution (Jazzy, Kilted; Humble when PHYTRACE_ROS_HUMBLE_SETUP names a
build of it: see rig.py)."""

from __future__ import annotations

import functools
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.processes import StubProcess
from tests.ros.rig import DISTROS, Rig, rclpy_missing

FLAVOURS = ("mock", *DISTROS)


@functools.cache
def why_no_rclpy(distro: str = "kilted") -> str | None:
    return rclpy_missing(distro)


@pytest.fixture(params=FLAVOURS)
def rig(request: pytest.FixtureRequest, tmp_path: Path, stub: StubProcess) -> Iterator[Rig]:
    if request.param != "mock" and (missing := why_no_rclpy(request.param)):
        if os.environ.get("CI"):  # in CI the real thing must run, never skip
            pytest.fail(missing)
        pytest.skip(missing)
    graph = Rig(request.param, tmp_path, stub)
    yield graph
    graph.close()
