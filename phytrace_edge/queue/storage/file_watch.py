"""Is the queue file still where QUEUE_PATH says? And if someone removed it, keep it.

People "clean up" robots: ``rm queue.db``, ``mv`` of the folder, a volume unmounted
under a running service. SQLite does not notice: it goes on writing to the file it has
open (in WAL mode even to a deleted one), and everything in it would vanish when the
process ends. So the store keeps a descriptor of the file it opened and compares it,
every heartbeat, with what the path names now (``look``):

- ``deleted``: the open file has no name left. It is copied to QUEUE_PATH from the open
  connection (SQLite's backup API), and the store goes on with the copy: the backlog is
  kept and the operator's ``rm`` becomes a logged event instead of a loss.
- ``moved``: the file was renamed; the folder is still there. Copied back the same way
  (the moved file is left where it was put: import or delete it by hand).
- ``replaced``: another file took its name. That file is moved aside
  (``<queue>.displaced-<time>``), never deleted, and the open file is copied back.
- ``folder_gone``: the queue's folder is gone (moved, removed, unmounted). The bridge
  does not make a new folder where a volume should be; it keeps writing to the open
  file and copies it back once the folder is there again.

Linux only (``/proc/self/fd`` names where a moved file is now); elsewhere ``open_path``
is None.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sqlite3
import time
from pathlib import Path
from typing import NamedTuple

from phytrace_edge.durable import sync_folder
from phytrace_edge.errors import QueueError
from phytrace_edge.queue.storage.database import Database

log = logging.getLogger(__name__)

OK, DELETED, MOVED, REPLACED, FOLDER_GONE = "ok", "deleted", "moved", "replaced", "folder_gone"
RESTORING_SUFFIX = ".restoring"


class FileState(NamedTuple):
    """What the queue path names now, compared with the file the store has open."""

    state: str  # OK, DELETED, MOVED, REPLACED or FOLDER_GONE
    open_path: str | None  # where the open file is now, as the kernel names it

    @property
    def restorable(self) -> bool:
        """Whether a copy can be put at the queue path now."""
        return self.state in (DELETED, MOVED, REPLACED)

    def describe(self, path: Path) -> str | None:
        """One line for the log and ``status``; None when all is well."""
        if self.state == OK:
            return None
        if self.state == DELETED:
            return f"the queue file {path} was deleted while the bridge had it open"
        if self.state == MOVED:
            return f"the queue file {path} was moved to {self.open_path}"
        if self.state == REPLACED:
            return f"the queue file {path} was replaced by another file"
        where = self.open_path or "?"
        if where.endswith(" (deleted)"):
            kept = (
                "the file the bridge has open was deleted with it: its events are lost "
                "at a stop unless the folder returns"
            )
        else:
            kept = f"events are kept in the file the bridge has open, now at {where}"
        return (
            f"the queue's folder {path.parent} is gone (moved, removed or unmounted); "
            f"{kept}; the bridge goes on with it and copies it back when the folder returns"
        )


class FileKeeper:
    """Watches the queue file of one store and copies it back when it is lost."""

    def __init__(self, db: Database, wal_reserve: int) -> None:
        self._db = db
        self._wal_reserve = wal_reserve
        self._descriptor = open_descriptor(db.path)  # the file, to know it again
        self.state = FileState(OK, str(db.path))
        self.restored = 0  # times the file was copied back to its path

    def watch(self) -> FileState:
        """Look at the path; copy the file back when that can be done (module doc)."""
        state = look(self._descriptor, self._db.path)
        if state != self.state:
            line = state.describe(self._db.path)
            if line:
                log.error("%s", line)
            else:
                log.warning("queue %s: the file is back at its path", self._db.path)
        self.state = state
        if state.restorable:
            self._restore(state)
        return self.state

    def _restore(self, state: FileState) -> None:
        """Copy the open database to its path and go on with the copy."""
        path = self._db.path
        with self._db.lock:
            try:
                if state.state == REPLACED:
                    move_aside(path)
                draft = copy_out(self._db.connection, path)
                self._db.reopen(lambda: install(draft, path))
                self._db.size_wal(self._wal_reserve)
                os.close(self._descriptor)
                self._descriptor = open_descriptor(path)
            except (OSError, sqlite3.Error, QueueError) as exc:
                log.error("queue %s: could not copy the open queue back: %s", path, exc)
                return
            self.restored += 1
            depth = self._db.counter("depth")
        self.state = look(self._descriptor, path)
        log.warning(
            "queue %s: copied the open queue back to its path (%d event(s) kept); the "
            "bridge goes on with the copy",
            path,
            depth,
        )

    def close(self) -> None:
        if self._descriptor >= 0:
            os.close(self._descriptor)
            self._descriptor = -1


def open_descriptor(path: Path) -> int:
    """A read-only descriptor of the queue file, kept to know it again."""
    return os.open(path, os.O_RDONLY | os.O_CLOEXEC)


def look(descriptor: int, path: Path) -> FileState:
    """Compare the open file with what ``path`` names now."""
    opened = os.fstat(descriptor)
    try:
        named = path.stat()
    except OSError:  # FileNotFoundError, or the folder itself is gone or unreadable
        named = None
    if named is not None and (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino):
        return FileState(OK, str(path))
    open_path = _open_path(descriptor)
    if not path.parent.is_dir():
        return FileState(FOLDER_GONE, open_path)
    if named is not None:
        return FileState(REPLACED, open_path)
    return FileState(DELETED if opened.st_nlink == 0 else MOVED, open_path)


def _open_path(descriptor: int) -> str | None:
    with contextlib.suppress(OSError):
        return str(Path(f"/proc/self/fd/{descriptor}").readlink())
    return None


def copy_out(connection: sqlite3.Connection, path: Path) -> Path:
    """Copy the database open on ``connection`` to a new file beside ``path``
    (``<queue>.restoring``), synced; ``install`` puts it in place once that connection
    is closed."""
    draft = path.with_name(path.name + RESTORING_SUFFIX)
    for stale in (draft, Path(f"{draft}-wal"), Path(f"{draft}-shm")):
        stale.unlink(missing_ok=True)
    os.close(os.open(draft, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))  # private
    target = sqlite3.connect(draft)
    try:
        connection.backup(target)
    finally:
        target.close()  # checkpoints the copy's own WAL into it and removes that WAL
    fd = os.open(draft, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return draft


def install(draft: Path, path: Path) -> None:
    """Rename the copy to the queue's name, durably. The old file's WAL and
    shared-memory files, still named after ``path`` (a file deleted or moved alone
    leaves them), are removed first: SQLite would apply them to the copy."""
    clear_side_files(path)
    draft.replace(path)
    sync_folder(path.parent)


def clear_side_files(path: Path) -> None:
    """Remove ``path``'s WAL and shared-memory files (the old file's, when it was
    deleted or moved alone)."""
    for suffix in ("-wal", "-shm"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


def move_aside(path: Path) -> Path:
    """Move a file that took the queue's name aside, never deleting it."""
    aside = path.with_name(f"{path.name}.displaced-{time.strftime('%Y%m%dT%H%M%S')}")
    path.replace(aside)
    log.error("queue %s: another file had taken its name; moved it aside to %s", path, aside)
    return aside
