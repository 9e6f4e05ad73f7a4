"""Who holds the queue: the running service, and every process with open claims.

- ``ServiceLock``: ``phytrace-edge run`` holds an exclusive lock on ``<queue>.lock``
  (its pid written in it), so a second ``run`` on the same file stops at once with one
  line naming the first. ``drain`` does not take it: it may run beside the service.
- ``Owner``: every open store holds a lock on its own file ``<queue>.owners/<token>``
  and marks its leases with that token. The kernel drops a process's locks when it
  dies, however it dies (kill -9, a killed container, a power cut), so another process
  can tell at once that a lease's owner is gone and take its events back, instead of
  waiting for the lease to run out.

Locks are ``flock``s: they hold across processes and containers that share the volume,
and are released by the kernel, never by a stale pid file.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import uuid
from pathlib import Path

from phytrace_edge.errors import QueueError


class ServiceLock:
    """The lock of the one service that runs on a queue file."""

    def __init__(self, queue_path: Path) -> None:
        self.path = Path(f"{queue_path}.lock")
        try:
            # the queue's folder, as the store would make it (0700: the events are private)
            self.path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            self._fd: int | None = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o600)
        except OSError as exc:
            raise QueueError(
                f"queue {queue_path}: cannot lock it ({exc.strerror}) - the queue's folder "
                "must be writable by the bridge"
            ) from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self._fd, 32, 0).decode("ascii", "replace").strip() or "?"
            self.release()
            raise QueueError(
                f"queue {queue_path} is in use by another phytrace-edge run (pid {holder}) "
                "- stop that one first, or set QUEUE_PATH to another file"
            ) from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing drops the lock
            self._fd = None


class Owner:
    """This process's claim to be alive, held for as long as its store is open."""

    def __init__(self, queue_path: Path) -> None:
        self.folder = Path(f"{queue_path}.owners")
        self.token = uuid.uuid4().hex
        self.folder.mkdir(mode=0o700, exist_ok=True)
        # locked before it gets its name: nobody can find it unlocked and think it dead
        draft = self.folder / f".{self.token}"
        self._fd: int | None = os.open(draft, os.O_CREAT | os.O_RDWR, 0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        draft.rename(self.folder / self.token)

    def close(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(FileNotFoundError):
                (self.folder / self.token).unlink()
            os.close(self._fd)
            self._fd = None


def is_alive(queue_path: Path, token: str) -> bool:
    """Whether the owner ``token`` of leases on this queue still runs. A dead owner's
    file is removed on the way."""
    path = Path(f"{queue_path}.owners") / token
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
    folder = Path(f"{queue_path}.owners")
    with contextlib.suppress(FileNotFoundError):
        for entry in folder.iterdir():
            if not entry.name.startswith("."):
                is_alive(queue_path, entry.name)
