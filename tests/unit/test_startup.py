"""status, --help and config import nothing outside the standard library, so the
container's health check (status every 30 s) and an operator's commands start fast
(tools/bench_startup.py measures it; docs/benchmarks.md has the figures). Each
third-party package (numpy, httpx, ...) costs more than the whole of ``status``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.processes import python_env

# What the command imported, beyond what the interpreter had at start (site's own
# imports, such as setuptools' _distutils_hack, are not the command's).
PROBE = """
import json, sys
before = set(sys.modules)
from phytrace_edge.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exit:
    code = exit.code
sys.stderr.write(json.dumps(sorted(set(sys.modules) - before)))
"""


def third_party(modules: set[str]) -> list[str]:
    """The loaded modules that are neither the standard library nor ours."""
    tops = {name.partition(".")[0] for name in modules}
    return sorted(tops - set(sys.stdlib_module_names) - {"phytrace_edge", "__main__"})


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
    assert third_party(loaded) == []


def test_status_reads_a_real_queue_without_the_store(tmp_path: Path) -> None:
    from phytrace_edge.queue.store import QueueStore

    with QueueStore.open(tmp_path / "q.db") as store:
        store.put({"event_id": "e1"})
    loaded = modules_after("status", "--json", QUEUE_PATH=str(tmp_path / "q.db"))
    assert "phytrace_edge.queue.peek" in loaded and "sqlite3" in loaded
    assert "phytrace_edge.queue.store" not in loaded  # the writer's side: not for reading
    assert third_party(loaded) == []


def test_the_rule_sees_a_third_party_import() -> None:
    loaded = modules_after("--help") | {"numpy", "numpy.core", "httpx._client"}
    assert third_party(loaded) == ["httpx", "numpy"]
