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

from phytrace_edge.errors import QueueBusyError, QueueError, QueueFullError

log = logging.getLogger(__name__)

# SQLite result codes (the sqlite3 module names them only from Python 3.11)
SQLITE_PERM, SQLITE_BUSY, SQLITE_LOCKED, SQLITE_READONLY = 3, 5, 6, 8
SQLITE_IOERR, SQLITE_CORRUPT, SQLITE_FULL, SQLITE_CANTOPEN = 10, 11, 13, 14
SQLITE_NOTADB = 26
_CODE_BY_TEXT = {
    "file is not a database": SQLITE_NOTADB,
    "database disk image is malformed": SQLITE_CORRUPT,
    "database is locked": SQLITE_BUSY,
    "database or disk is full": SQLITE_FULL,
    "unable to open database file": SQLITE_CANTOPEN,
    "attempt to write a readonly database": SQLITE_READONLY,
    "disk I/O error": SQLITE_IOERR,
}
# what the operator should do about each, after "queue PATH: "
_HINTS = {
    SQLITE_FULL: "disk full - free space on the volume or lower QUEUE_MAX_BYTES",
    SQLITE_BUSY: "locked by another process past the busy timeout - is another bridge "
    "or a long drain using this queue?",
    SQLITE_READONLY: "read-only - the queue file and its folder must be writable by the bridge",
    SQLITE_CANTOPEN: "cannot open - check QUEUE_PATH, and that its folder exists and is "
    "readable by this user",
    SQLITE_PERM: "permission denied - run as the bridge's user or fix the file's owner",
    SQLITE_IOERR: "disk I/O error - check the disk (dmesg) and free space",
    SQLITE_CORRUPT: "damaged - the bridge moves such a file aside at its next start",
    SQLITE_NOTADB: "not a SQLite database - check QUEUE_PATH; the bridge moves a foreign "
    "file aside at its next start",
}
_HINTS[SQLITE_LOCKED] = _HINTS[SQLITE_BUSY]


def sqlite_code(exc: sqlite3.Error) -> int | None:
    """The primary SQLite result code of an error (from its text on Python 3.10)."""
    code = getattr(exc, "sqlite_errorcode", None)
    if code is not None:
        return int(code) & 0xFF
    return next((c for text, c in _CODE_BY_TEXT.items() if text in str(exc)), None)


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


def queue_error(exc: sqlite3.Error, path: Path) -> QueueError:
    """Map a SQLite error to the queue error type, with a message that says what to do."""
    code = sqlite_code(exc)
    message = f"queue {path}: {_HINTS.get(code, str(exc)) if code is not None else exc}"
    if code == SQLITE_FULL:
        return QueueFullError(message)
    if code in (SQLITE_BUSY, SQLITE_LOCKED):
        return QueueBusyError(message)
    return QueueError(message)
