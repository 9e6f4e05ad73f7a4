"""Opening the queue file safely: permissions, integrity check, quarantine.

A queue file that is corrupt or is not SQLite at all must never brick the bridge (as
corrupt buffer files have bricked other agents) and must never be deleted: it is moved
aside with a timestamped name, reported at ERROR, and a fresh queue starts. A file that
is merely busy or unreadable is *not* corrupt and is never moved.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import time
from pathlib import Path

from phytrace_edge.errors import QueueBusyError, QueueError
from phytrace_edge.queue.sqlite_errors import (
    SQLITE_BUSY,
    SQLITE_CORRUPT,
    SQLITE_LOCKED,
    SQLITE_NOTADB,
    sqlite_code,
)

log = logging.getLogger(__name__)


def connect(path: Path, busy_timeout_s: float) -> sqlite3.Connection:
    """A connection in autocommit mode (transactions are explicit)."""
    connection = sqlite3.connect(
        path, timeout=busy_timeout_s, isolation_level=None, check_same_thread=False
    )
    connection.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
    return connection


def open_checked(path: Path, busy_timeout_s: float) -> tuple[sqlite3.Connection, Path | None]:
    """Open the queue at ``path`` in WAL mode; (connection, where a bad file was moved)."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    quarantined = None
    if path.exists() and path.stat().st_size > 0:
        problem = _integrity_problem(path, busy_timeout_s)
        if problem is not None:
            quarantined = quarantine(path, problem)
    _create_private(path)
    try:
        connection = connect(path, busy_timeout_s)
        mode = connection.execute("PRAGMA journal_mode = WAL").fetchone()[0]
    except sqlite3.Error as exc:
        raise QueueError(f"queue {path}: cannot open ({exc})") from exc
    if mode != "wal":
        raise QueueError(
            f"queue {path}: cannot use WAL mode (got {mode}) - is it on a network share?"
        )
    return connection, quarantined


def _integrity_problem(path: Path, busy_timeout_s: float) -> str | None:
    """What is wrong with an existing file, or None if it is a sound SQLite database."""
    try:
        connection = connect(path, busy_timeout_s)
        try:
            result = connection.execute("PRAGMA quick_check").fetchone()[0]
        finally:
            connection.close()
    except sqlite3.Error as exc:
        code = sqlite_code(exc)
        if code in (SQLITE_CORRUPT, SQLITE_NOTADB):
            return str(exc)
        if code in (SQLITE_BUSY, SQLITE_LOCKED):
            raise QueueBusyError(f"queue {path}: locked by another process") from exc
        raise QueueError(f"queue {path}: cannot read ({exc})") from exc
    return None if result == "ok" else f"quick_check: {result}"


def quarantine(path: Path, problem: str) -> Path:
    """Move a bad queue file (and its -wal/-shm) aside; never delete it."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    target = path.with_name(f"{path.name}.corrupt-{stamp}")
    serial = 1
    while target.exists():
        serial += 1
        target = path.with_name(f"{path.name}.corrupt-{stamp}-{serial}")
    path.rename(target)
    for suffix in ("-wal", "-shm"):
        companion = Path(f"{path}{suffix}")
        if companion.exists():
            companion.rename(Path(f"{target}{suffix}"))
    log.error(
        "queue %s is unreadable (%s): moved to %s and started a fresh queue; the old file is "
        "kept for inspection (sqlite3 %s '.recover')",
        path,
        problem,
        target,
        target,
    )
    return target


def _create_private(path: Path) -> None:
    """Create the file with mode 0600 before SQLite does (its -wal/-shm inherit it)."""
    descriptor = os.open(path, os.O_CREAT | os.O_RDWR, 0o600)
    os.close(descriptor)
    path.chmod(0o600)
