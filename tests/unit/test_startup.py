"""status, --help and config import only what they use, so the container's health
check (status every 30 s) and an operator's commands start fast (tools/bench_startup.py
measures it; docs/benchmarks.md has the figures)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.processes import python_env

# Each of these would cost more start-up time than the whole of `status` needs.
HEAVY = (
    "numpy",
    "httpx",
    "tenacity",
    "orjson",
    "zstandard",
    "fastjsonschema",
    "prometheus_client",
    "tqdm",
    "phytrace_edge.ingest.handlers",
    "phytrace_edge.queue.store",
    "dataclasses",
    "typing",
    "logging",
    "pathlib",
    "threading",
)
PROBE = """
import json, sys
from phytrace_edge.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exit:
    code = exit.code
sys.stderr.write(json.dumps(sorted(sys.modules)))
"""


def modules_after(*argv: str, **env: str) -> set[str]:
    result = subprocess.run(
        [sys.executable, "-c", PROBE, *argv],
        capture_output=True,
        text=True,
        timeout=60,
        env=python_env(**env),
    )
    return set(json.loads(result.stderr.strip().splitlines()[-1]))


@pytest.mark.parametrize("argv", [("status", "--json"), ("--help",), ("config",)])
def test_a_quick_command_imports_nothing_heavy(tmp_path: Path, argv: tuple[str, ...]) -> None:
    loaded = modules_after(*argv, QUEUE_PATH=str(tmp_path / "none.db"))
    assert "phytrace_edge.config" in loaded  # it did load the settings
    assert not set(HEAVY) & loaded, sorted(set(HEAVY) & loaded)


def test_status_reads_a_real_queue_without_the_store(tmp_path: Path) -> None:
    from phytrace_edge.queue.store import QueueStore

    with QueueStore.open(tmp_path / "q.db") as store:
        store.put({"event_id": "e1"})
    loaded = modules_after("status", "--json", QUEUE_PATH=str(tmp_path / "q.db"))
    assert "phytrace_edge.queue.inspect" in loaded and "sqlite3" in loaded
    assert not set(HEAVY) & loaded, sorted(set(HEAVY) & loaded)
