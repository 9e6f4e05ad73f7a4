"""The running service's status outside the queue's volume.

The heartbeat row in the queue file is what ``status`` reads; but when that volume
fails (I/O errors, read-only, unmounted, the file deleted) the row cannot be written,
and ``status`` would call a service that is working hard to keep its events "hung or
died". So every heartbeat also writes the same document, with the queue's counters and
the disk's figures, to a small file in memory-backed runtime storage, and ``status``
prefers it while it is fresh.

Where: ``$RUNTIME_DIRECTORY`` (systemd's ``RuntimeDirectory=``), else
``/run/phytrace-edge``, else ``/dev/shm``, else the temporary folder; the file is named
after the queue's absolute path, so ``status`` with the same QUEUE_PATH finds it from
any shell. Times in it are ``CLOCK_BOOTTIME`` (shared by every process of a boot; the
file does not outlive the boot). Standard library only: on ``status``'s start-up path.
"""

import contextlib
import hashlib
import json
import os
import tempfile
import time
from collections.abc import Mapping
from typing import Any

RUN_FOLDER = "/run/phytrace-edge"


def boottime() -> float:
    return time.clock_gettime(time.CLOCK_BOOTTIME)


def _folders(env: Mapping[str, str]) -> list[str]:
    folders = []
    if env.get("RUNTIME_DIRECTORY"):
        folders.append(env["RUNTIME_DIRECTORY"].split(":")[0])
    # /dev/shm: memory-backed in a container too; the file is 0600 and named, not guessed
    folders += [RUN_FOLDER, "/dev/shm", tempfile.gettempdir()]  # noqa: S108
    return folders


def _name(queue_path: str) -> str:
    digest = hashlib.sha256(os.path.abspath(queue_path).encode()).hexdigest()[:16]
    return f"phytrace-edge-{digest}.json"


def writable_path(queue_path: str, env: Mapping[str, str]) -> str | None:
    """Where the service writes its live status: the first usable folder (made when it
    is ``/run/phytrace-edge`` and /run is writable)."""
    for folder in _folders(env):
        if folder == RUN_FOLDER and not os.path.isdir(folder):
            with contextlib.suppress(OSError):
                os.mkdir(folder, 0o755)
        if os.path.isdir(folder) and os.access(folder, os.W_OK | os.X_OK):
            return os.path.join(folder, _name(queue_path))
    return None


def write(path: str, document: dict[str, Any]) -> None:
    """Replace the file at ``path`` with ``document``, atomically (a reader never sees
    half of it). No fsync: it lives in memory and describes only this boot."""
    draft = f"{path}.{os.getpid()}.tmp"
    fd = os.open(draft, os.O_CREAT | os.O_TRUNC | os.O_WRONLY, 0o600)
    try:
        os.write(fd, json.dumps(document).encode())
    finally:
        os.close(fd)
    os.replace(draft, path)


def read(queue_path: str, env: Mapping[str, str]) -> dict[str, Any] | None:
    """The newest live status written for ``queue_path``, or None."""
    found = find(queue_path, env)
    return None if found is None else found[1]


def find(queue_path: str, env: Mapping[str, str]) -> tuple[str, dict[str, Any]] | None:
    """Where the newest live status for ``queue_path`` is, and what it says."""
    newest: tuple[str, dict[str, Any]] | None = None
    for folder in _folders(env):
        path = os.path.join(folder, _name(queue_path))
        try:
            with open(path, "rb") as file:
                document = json.loads(file.read())
        except (OSError, ValueError):
            continue
        if isinstance(document, dict) and (
            newest is None or document.get("boottime", 0) > newest[1].get("boottime", 0)
        ):
            newest = (path, document)
    return newest


def remove(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)
