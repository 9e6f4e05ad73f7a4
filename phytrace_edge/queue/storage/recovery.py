"""Opening the queue file safely: its place, permissions, integrity, schema, quarantine.

A queue file that is corrupt, is not SQLite at all, or is another application's
database must never brick the bridge (as corrupt buffer files have bricked other
agents) and must never be deleted or changed: it is moved aside with a timestamped
name, reported at ERROR, and a fresh queue starts. A file that is merely busy or
unreadable is *not* corrupt and is never moved. A queue written by a newer version is
refused, not used. The path must be a regular file, or a missing one the bridge then
creates with mode 0600; nothing else is ever chmod'ed or opened (``/dev/null`` as root
would otherwise be made 0600 for every process of the robot).

Checking costs time in proportion to the file (3.6 s for a million events), and the
bridge starts and ``drain`` runs often, so the open checks the header, the schema and
as much of ``PRAGMA quick_check`` as ``OPEN_CHECK_S`` allows; a small queue is checked
whole. The maintenance loop finishes the check on its own connection
(``check_integrity``). A file it finds damaged is marked (``<queue>.damaged``) and
reported, and the next open checks it whole and moves it aside.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import stat
import time
from pathlib import Path
from typing import NamedTuple

from phytrace_edge.errors import QueueBusyError, QueueError
from phytrace_edge.queue.peek import DAMAGED_SUFFIX
from phytrace_edge.queue.storage.migrate import latest_version
from phytrace_edge.queue.storage.sqlite_errors import (
    SQLITE_BUSY,
    SQLITE_CORRUPT,
    SQLITE_LOCKED,
    SQLITE_NOTADB,
    sqlite_code,
)

log = logging.getLogger(__name__)

OPEN_CHECK_S = 0.3
PROGRESS_STEPS = 20_000  # SQLite VM steps between looks at the clock


def connect(path: Path, busy_timeout_s: float) -> sqlite3.Connection:
    """A connection in autocommit mode (transactions are explicit)."""
    connection = sqlite3.connect(
        path, timeout=busy_timeout_s, isolation_level=None, check_same_thread=False
    )
    connection.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
    return connection


class Opened(NamedTuple):
    """The queue file, opened and checked."""

    connection: sqlite3.Connection
    quarantined: Path | None  # where a damaged file was moved aside, if one was
    checked_whole: bool  # False: the check ran out of time (the file is large)


def open_checked(path: Path, busy_timeout_s: float) -> Opened:
    """Open the queue at ``path`` in WAL mode, after checking it."""
    exists = _check_place(path)
    quarantined, whole = None, True
    if exists and path.stat().st_size > 0:
        marked = damage_marker(path)
        budget = None if marked.exists() else OPEN_CHECK_S
        problem, whole = _integrity_problem(path, busy_timeout_s, budget)
        if problem is not None:
            quarantined = quarantine(path, problem)
            exists = False
        if whole:
            marked.unlink(missing_ok=True)
    if not exists:
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
    return Opened(connection, quarantined, whole)


def damage_marker(path: Path) -> Path:
    """The file that says a check found ``path`` damaged while it was in use."""
    return Path(f"{path}{DAMAGED_SUFFIX}")


def quick_check(connection: sqlite3.Connection, budget_s: float | None) -> str | None:
    """``PRAGMA quick_check``'s verdict ("ok" or the first problems), or None when it
    ran past ``budget_s`` and was stopped."""
    if budget_s is not None:
        deadline = time.monotonic() + budget_s
        connection.set_progress_handler(lambda: time.monotonic() > deadline, PROGRESS_STEPS)
    try:
        return str(connection.execute("PRAGMA quick_check(10)").fetchone()[0])
    except sqlite3.OperationalError as exc:
        if budget_s is not None and "interrupted" in str(exc):
            return None
        raise
    finally:
        connection.set_progress_handler(None, 0)


def check_integrity(path: Path, busy_timeout_s: float) -> str | None:
    """The whole check, on a connection of its own (the queue stays in use): None when
    the file is sound, else the problem, which is also reported and marked for the
    next open to move the file aside."""
    connection = connect(path, busy_timeout_s)
    try:
        verdict = quick_check(connection, None)
    except sqlite3.DatabaseError as exc:
        verdict = str(exc)
    finally:
        connection.close()
    if verdict == "ok":
        return None
    problem = f"quick_check: {verdict}"
    mark_damaged(path, problem)
    return problem


def mark_damaged(path: Path, problem: str) -> None:
    """Report damage found while the queue is in use, and mark the file so that the
    next open checks it whole (and moves it aside). Marked once: later errors of the
    same damage are not reported again."""
    marker = damage_marker(path)
    if marker.exists():
        return
    try:
        marker.write_text(problem + "\n", "utf-8")
    except OSError as exc:
        log.error("queue %s: cannot write %s (%s)", path, marker, exc.strerror)
    log.error(
        "queue %s is damaged (%s): restart the bridge to move it aside and start a fresh "
        "queue; events that can still be read are sent meanwhile",
        path,
        problem,
    )


def _check_place(path: Path) -> bool:
    """Whether a queue file exists at ``path``; raises a one-line QueueError for a path
    that is not a regular file, or whose folder cannot be made."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        try:
            path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        except OSError as exc:
            raise QueueError(
                f"queue {path}: cannot create its folder ({exc.strerror}) - check QUEUE_PATH"
            ) from None
        return False
    except OSError as exc:
        raise QueueError(f"queue {path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise QueueError(f"queue {path}: not a regular file - set QUEUE_PATH to a file")
    return True


def _integrity_problem(
    path: Path, busy_timeout_s: float, budget_s: float | None
) -> tuple[str | None, bool]:
    """(What is wrong with an existing file or None if it is a sound queue database,
    whether the check covered the whole file). Raises QueueError for a queue of a newer
    version (not ours to change)."""
    try:
        connection = connect(path, busy_timeout_s)
        try:
            version = connection.execute("PRAGMA user_version").fetchone()[0]
            tables = {name for (name,) in connection.execute("SELECT name FROM sqlite_master")}
            result = quick_check(connection, budget_s)
        finally:
            connection.close()
    except sqlite3.Error as exc:
        code = sqlite_code(exc)
        if code in (SQLITE_CORRUPT, SQLITE_NOTADB):
            return str(exc), True
        if code in (SQLITE_BUSY, SQLITE_LOCKED):
            raise QueueBusyError(f"queue {path}: locked by another process") from exc
        raise QueueError(f"queue {path}: cannot read ({exc})") from exc
    if result not in ("ok", None):
        return f"quick_check: {result}", True
    if (version == 0 and tables) or (version > 0 and "counters" not in tables):
        return f"not a phytrace-edge queue (tables: {', '.join(sorted(tables))[:200]})", True
    if version > latest_version():
        raise QueueError(
            f"queue {path}: written by a newer phytrace-edge (schema version {version}; this "
            f"one knows up to {latest_version()}) - upgrade phytrace-edge or set QUEUE_PATH "
            "to another file"
        )
    return None, result is not None


def quarantine(path: Path, problem: str) -> Path:
    """Move a bad queue file (and its -wal/-shm) aside; never delete it."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    target = path.with_name(f"{path.name}.corrupt-{stamp}")
    serial = 1
    while target.exists():
        serial += 1
        target = path.with_name(f"{path.name}.corrupt-{stamp}-{serial}")
    try:
        path.rename(target)
        for suffix in ("-wal", "-shm"):
            companion = Path(f"{path}{suffix}")
            if companion.exists():
                companion.rename(Path(f"{target}{suffix}"))
    except OSError as exc:
        raise QueueError(
            f"queue {path} is unusable ({problem}) and cannot be moved aside "
            f"({exc.strerror}) - move it away by hand or set QUEUE_PATH to another file"
        ) from None
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
    """Create the file with mode 0600 before SQLite does (its -wal/-shm inherit it).
    Only a file created here is given that mode: nothing else is ever chmod'ed."""
    try:
        descriptor = os.open(path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o600)
    except FileExistsError:  # created since we looked: another process's, leave it be
        return
    except OSError as exc:
        raise QueueError(
            f"queue {path}: cannot create it ({exc.strerror}) - the queue's folder must be "
            "writable by the bridge"
        ) from None
    os.close(descriptor)
    os.chmod(path, 0o600)  # noqa: PTH101 - the umask may have taken bits off
