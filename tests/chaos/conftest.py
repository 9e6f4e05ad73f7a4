from __future__ import annotations

from pathlib import Path

import pytest

from tests.chaos.machine_time import faketime_env


@pytest.fixture
def faked_clock(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """(the environment that fakes a process's wall clock, the file that sets it)."""
    return faketime_env(tmp_path)
