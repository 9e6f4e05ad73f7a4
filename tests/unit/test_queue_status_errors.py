"""``phytrace-edge status`` on a QUEUE_PATH that is not a readable queue: one line on
stderr naming the path and what to do, exit 4, and the file left as it was
(``queue/peek.py``'s ``read_stats``, ``queue/storage/sqlite_errors.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from phytrace_edge.cli import main
from phytrace_edge.errors import QueueDamagedError
from phytrace_edge.queue.peek import read_stats


def status_error(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``phytrace-edge status`` on ``path``: its exit code and the one line on stderr."""
    code = main(["status", "--queue-path", str(path)])
    said = capsys.readouterr()
    assert said.out == ""
    (line,) = [
        line for line in said.err.splitlines() if not line.startswith("phytrace-edge: warning:")
    ]
    return code, line


def test_status_on_a_folder_says_to_set_queue_path_to_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """QUEUE_PATH set to the queue's folder (a common slip): status says which path is
    wrong and what it must be, in one line, instead of a bare "None"."""
    code, line = status_error(tmp_path, capsys)
    assert code == 4
    assert line == (
        f"phytrace-edge: error: queue {tmp_path}: not a regular file - set QUEUE_PATH to "
        "the queue file"
    )


def test_status_on_another_file_says_it_is_not_a_database_and_leaves_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """QUEUE_PATH pointed at a file that is not SQLite (a log, a config): status says
    so in one line naming it, and what the bridge will do with it, without touching
    it; not a traceback, and not "None"."""
    path = tmp_path / "bridge.log"
    text = b"2026-01-01 started\n" * 400
    path.write_bytes(text)
    code, line = status_error(path, capsys)
    assert code == 4
    assert line == (
        f"phytrace-edge: error: queue {path}: not a SQLite database - check QUEUE_PATH; the "
        "bridge moves a foreign file aside at its next start"
    )
    assert path.read_bytes() == text
    with pytest.raises(QueueDamagedError):  # the type the store marks damage by
        read_stats(str(path))
