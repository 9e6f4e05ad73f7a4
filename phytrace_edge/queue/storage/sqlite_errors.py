"""SQLite errors mapped to the queue's errors, each with what the operator should do.

Every module of ``queue/`` that touches SQLite raises through ``queue_error``, so no
``sqlite3`` exception leaves the package. Stdlib only: ``status`` uses it at start-up.
"""

from __future__ import annotations

import errno
import os
import sqlite3

from phytrace_edge.errors import QueueBusyError, QueueDamagedError, QueueError, QueueFullError

# SQLite result codes (the sqlite3 module names them only from Python 3.11)
SQLITE_PERM, SQLITE_BUSY, SQLITE_LOCKED, SQLITE_READONLY = 3, 5, 6, 8
SQLITE_IOERR, SQLITE_CORRUPT, SQLITE_FULL, SQLITE_CANTOPEN = 10, 11, 13, 14
SQLITE_NOTADB = 26
FULL_BELOW_BYTES = 64 * 1024
_CODE_BY_TEXT = {
    "file is not a database": SQLITE_NOTADB,
    "database disk image is malformed": SQLITE_CORRUPT,
    "malformed database schema": SQLITE_CORRUPT,  # a damaged sqlite_schema
    "database is locked": SQLITE_BUSY,
    "database table is locked": SQLITE_LOCKED,
    "database schema is locked": SQLITE_LOCKED,
    "access permission denied": SQLITE_PERM,
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


def io_cause(path: object) -> str | None:
    """What the file system says about the queue file when SQLite reports only a "disk
    I/O error": a read-only volume (ext4 remounts itself read-only after an error), a
    folder that is gone, a full volume. Opening for writing writes nothing."""
    folder = os.path.dirname(os.path.abspath(str(path)))
    if not os.path.isdir(folder):
        return "the queue's folder is gone"
    try:
        os.close(os.open(str(path), os.O_WRONLY | os.O_CLOEXEC))
    except OSError as exc:
        if exc.errno != errno.ENOENT:
            return f"{exc.strerror.lower() if exc.strerror else exc}"
    free = os.statvfs(folder)
    if free.f_bavail * free.f_frsize < FULL_BELOW_BYTES:
        return "no space left on the volume"
    return None


def queue_error(exc: sqlite3.Error, path: object) -> QueueError:
    """Map a SQLite error to the queue error type, with a message that says what to do."""
    code = sqlite_code(exc)
    message = f"queue {path}: {_HINTS.get(code, str(exc)) if code is not None else exc}"
    if code == SQLITE_IOERR and (cause := io_cause(path)) is not None:
        message = f"queue {path}: disk I/O error: {cause} - check the disk (dmesg) and its mount"
    if code == SQLITE_FULL:
        return QueueFullError(message)
    if code in (SQLITE_BUSY, SQLITE_LOCKED):
        return QueueBusyError(message)
    if code in (SQLITE_CORRUPT, SQLITE_NOTADB):
        return QueueDamagedError(message)
    return QueueError(message)
