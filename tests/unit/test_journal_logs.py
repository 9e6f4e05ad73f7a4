"""Under systemd the log carries journal priorities (sd-daemon(3)), so `journalctl -p
warning` finds warnings and errors; anywhere else the lines are unchanged."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.processes import python_env

LOGS = """
import logging, os
from phytrace_edge.runtime.logs import configure_logging
configure_logging("INFO", os.environ["FMT"], env=os.environ)
log = logging.getLogger("phytrace_edge.test")
log.info("all well")
log.warning("queue is 85% full")
try:
    1 / 0
except ZeroDivisionError:
    log.exception("send failed")
"""


def run_logging(tmp_path: Path, fmt: str, journal: bool) -> list[str]:
    """Log a few records with stderr on a file that is (or is not) the journal stream."""
    stderr = tmp_path / f"stderr-{fmt}-{journal}"
    with stderr.open("w") as handle:
        info = os.fstat(handle.fileno())
        env = python_env(FMT=fmt)
        if journal:  # as systemd sets it: device:inode of the stream it connected
            env["JOURNAL_STREAM"] = f"{info.st_dev}:{info.st_ino}"
        else:
            env["JOURNAL_STREAM"] = "1:2"  # another stream (stderr was redirected)
        subprocess.run([sys.executable, "-c", LOGS], stderr=handle, env=env, timeout=60, check=True)
    return stderr.read_text().splitlines()


def test_each_line_starts_with_its_priority_when_stderr_is_the_journal(tmp_path: Path) -> None:
    for fmt in ("text", "json"):
        lines = run_logging(tmp_path, fmt, journal=True)
        assert lines[0].startswith("<6>") and "all well" in lines[0]
        assert lines[1].startswith("<4>") and "85% full" in lines[1]
        assert lines[2].startswith("<3>") and "send failed" in lines[2]
        assert all(line.startswith("<3>") for line in lines[2:])  # the traceback's too
        assert len(lines) >= (3 if fmt == "json" else 5)


def test_elsewhere_lines_are_unchanged(tmp_path: Path) -> None:
    lines = run_logging(tmp_path, "text", journal=False)
    assert not any(line.startswith("<") for line in lines)
    assert " WARNING phytrace_edge.test: queue is 85% full" in lines[1]
