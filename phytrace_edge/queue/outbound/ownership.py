"""Who holds the queue: the running service, and every process with open claims.

- ``ServiceLock``: ``phytrace-edge run`` holds an exclusive lock on ``<queue>.lock``
  (its pid and its name of the queue written in it) and one on the queue file itself,
  so a second ``run`` on the same file stops at once with one line naming the first.
  ``drain`` does not take it: it may run beside the service.
- ``Owner``: every open store holds a lock on its own file ``<queue>.owners/<token>``
  and marks its leases with that token. The kernel drops a process's locks when it
  dies, however it dies (kill -9, a killed container, a power cut), so another process
  can tell at once that a lease's owner is gone and take its events back, instead of
  waiting for the lease to run out.

Every name derived from the queue's (``.lock``, ``.owners``) is made from its *real*
path (``os.path.realpath``: relative paths, ``./``, symlinks to the file or to a folder
on the way all give one name), so that every process on one file finds the same lock
and the same owners, whatever QUEUE_PATH it was given: two processes that looked in two
owners folders would each think the other's leases orphaned and take them back. A bind
mount (or a container's volume) is another path to the same folder, hence to the same
files beside the queue. A hard link is another name of the same file in a folder of its
own: the lock on the queue file itself catches that one.

Locks are ``flock``s: they hold across processes and containers that share the volume,
and are released by the kernel, never by a stale pid file.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import stat
import uuid
from pathlib import Path

from phytrace_edge.errors import QueueError

# a write flock in /proc/locks: "7: FLOCK  ADVISORY  WRITE <pid> <maj>:<min>:<inode> 0 EOF"
# (a waiter's line has "->" after the number, and does not match)
_FLOCK_LINE = re.compile(r"^\d+: FLOCK\s+\S+\s+WRITE\s+(\d+)\s+([0-9a-f]+:[0-9a-f]+:\d+)\s", re.M)


def real_name(queue_path: Path) -> str:
    """The name every process on this queue file agrees on (see the module doc)."""
    return os.path.realpath(queue_path)


def owners_folder(queue_path: Path) -> Path:
    """Where the owners of leases on this queue file hold their locks."""
    return Path(f"{real_name(queue_path)}.owners")


class ServiceLock:
    """The lock of the one service that runs on a queue file."""

    def __init__(self, queue_path: Path) -> None:
        real = real_name(queue_path)
        self.path = Path(f"{real}.lock")
        self._fd: int | None = None
        self._file_fd: int | None = None
        try:
            # the queue's folder, as the store would make it (0700: the events are private)
            self.path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            self._fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o600)
        except OSError as exc:
            raise QueueError(
                f"queue {queue_path}: cannot lock it ({exc.strerror}) - the queue's folder "
                "must be writable by the bridge"
            ) from None
        try:  # held through this name, or any other that resolves to the same
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _written_holder(self._fd)
            self.release()
            raise _in_use(queue_path, *holder) from None
        self._file_fd, linked = _lock_queue_file(Path(real))
        if linked is not None:  # held through a name of its own: a hard link
            self.release()
            raise _in_use(queue_path, *linked, hard_link=True)
        given = os.path.abspath(queue_path)  # noqa: PTH100 - the name as given, unresolved
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n{given}\n".encode(), 0)

    def release(self) -> None:
        """Drop the locks. Only once the store is closed: closing a descriptor of the
        queue file drops every POSIX lock this process holds on that file, SQLite's
        own included."""
        for fd in (self._file_fd, self._fd):
            if fd is not None:
                os.close(fd)  # closing drops the lock
        self._fd = self._file_fd = None


def _lock_queue_file(path: Path) -> tuple[int | None, tuple[str, str | None] | None]:
    """(a descriptor of the queue file itself, locked; None where it cannot be, with
    the holder's (pid, name) when another process has it). The file is made on a first
    start (0600, as the store would make it): a hard link made later is then a name of
    a locked file.

    SQLite locks the file with POSIX (``fcntl``) locks; on Linux's local file systems
    an ``flock`` does not interact with those, so this lock never gets in the way of
    SQLite's (this process's, or a ``drain``'s). On NFS the kernel emulates ``flock``
    with a whole-file ``fcntl`` lock, which would: there a read-only descriptor cannot
    take an exclusive ``flock`` at all, and the ``.lock`` file alone is left (SQLite's
    WAL mode does not work on NFS anyway). Not locked either: what is not a regular
    file, which is never opened (a device: the store refuses it), and a file this
    process cannot read (the store says why)."""
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_RDONLY, 0o600)
    except FileExistsError:
        try:
            if not stat.S_ISREG(path.stat().st_mode):
                return None, None
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
        except OSError:
            return None, None
    except OSError:
        return None, None
    else:
        with contextlib.suppress(OSError):
            os.fchmod(fd, 0o600)  # the umask may have taken bits off
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):  # not swapped for something else since
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return fd, None
    except BlockingIOError:
        holder = _holder_of(fd)
        os.close(fd)
        return None, holder
    except OSError:
        pass
    os.close(fd)
    return None, None


def _written_holder(fd: int) -> tuple[str, str | None]:
    """(pid, its name of the queue) as the holder of ``<queue>.lock`` wrote them ("?"
    before it has; an older version wrote only its pid)."""
    lines = os.pread(fd, 8192, 0).decode("utf-8", "replace").splitlines()
    pid = lines[0].strip() if lines and lines[0].strip() else "?"
    return pid, lines[1].strip() if len(lines) > 1 and lines[1].strip() else None


def _holder_of(fd: int) -> tuple[str, str | None]:
    """(pid, its name of the file) of the process holding the ``flock`` on the queue
    file (through a name of its own): the kernel's table of locks says the pid, the
    holder's descriptors its name. "?" and None where /proc does not tell (a process of
    another container, of another user)."""
    mine = os.fstat(fd)
    device = f"{os.major(mine.st_dev):02x}:{os.minor(mine.st_dev):02x}"
    try:
        table = Path("/proc/locks").read_text()
    except OSError:
        return "?", None
    found = "?"
    for match in _FLOCK_LINE.finditer(table):
        pid, on = match.group(1), match.group(2)
        if on.endswith(f":{mine.st_ino}") and pid != "0":  # 0: not in our pid namespace
            name = _name_in(pid, mine, skip=fd if pid == str(os.getpid()) else None)
            if name is not None:
                return pid, name
            if on == f"{device}:{mine.st_ino}":  # a file system that says its device
                found = pid
    return found, None


def _name_in(pid: str, file: os.stat_result, skip: int | None) -> str | None:
    """The name by which process ``pid`` has ``file`` open, if it does and we may see."""
    with contextlib.suppress(OSError):
        for entry in Path(f"/proc/{pid}/fd").iterdir():
            with contextlib.suppress(OSError):
                held = entry.stat()  # of the file the descriptor is open on
                same = (held.st_dev, held.st_ino) == (file.st_dev, file.st_ino)
                if same and entry.name != str(skip):
                    return str(entry.readlink())
    return None


def _in_use(queue_path: Path, pid: str, name: str | None, hard_link: bool = False) -> QueueError:
    if name is not None:
        through = f" through {name}" + (", another name of this file" if hard_link else "")
    else:
        through = " through another name of this file (a hard link)" if hard_link else ""
    return QueueError(
        f"queue {queue_path} is in use by another phytrace-edge run (pid {pid}){through} "
        "- stop that one first, or set QUEUE_PATH to another file"
    )


class Owner:
    """This process's claim to be alive, held for as long as its store is open."""

    def __init__(self, queue_path: Path) -> None:
        self.folder = owners_folder(queue_path)
        self.token = uuid.uuid4().hex
        self.folder.mkdir(mode=0o700, exist_ok=True)
        # locked before it gets its name: nobody can find it unlocked and think it dead
        draft = self.folder / f".{self.token}"
        self._fd: int | None = os.open(draft, os.O_CREAT | os.O_RDWR, 0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        draft.rename(self.folder / self.token)

    def close(self) -> None:
        if self._fd is not None:
            # gone, or on a volume gone read-only: the lock ends with the descriptor,
            # and a file left behind is swept as a dead owner's
            with contextlib.suppress(OSError):
                (self.folder / self.token).unlink()
            os.close(self._fd)
            self._fd = None


def is_alive(queue_path: Path, token: str) -> bool:
    """Whether the owner ``token`` of leases on this queue still runs. A dead owner's
    file is removed on the way."""
    path = owners_folder(queue_path) / token
    try:
        fd = os.open(path, os.O_RDWR)
    except (FileNotFoundError, NotADirectoryError):
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        return False
    finally:
        os.close(fd)


def dead_owners(queue_path: Path, claim_owners: set[str], own_token: str) -> list[str]:
    """The owner tokens among these claims' (``<owner token>:<claim>``) whose process
    is gone, this process's own excepted."""
    tokens = {owner.split(":", 1)[0] for owner in claim_owners} - {own_token}
    return [token for token in tokens if not is_alive(queue_path, token)]


def sweep_dead_owners(queue_path: Path) -> None:
    """Remove the files of owners that died without leases (they would pile up)."""
    folder = owners_folder(queue_path)
    with contextlib.suppress(FileNotFoundError):
        for entry in folder.iterdir():
            if not entry.name.startswith("."):
                is_alive(queue_path, entry.name)
