"""The service lock and the owners folder, keyed on the queue file itself, whatever
path names it (issue 31, item 9). In one process: the lock is an ``flock`` per open
file, so a second lock in the same process is refused like a second process would be.
Real processes: tests/hostile/test_queue_ownership.py."""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.outbound.ownership import Owner, ServiceLock, dead_owners, is_alive


def relative(queue: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(queue.parent.parent)
    return Path("data/../data/queue.db")


def symlink_to_file(queue: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (queue.parent / "alias.db").symlink_to("queue.db")
    return queue.parent / "alias.db"


def symlink_to_folder(queue: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (queue.parent.parent / "linked").symlink_to(queue.parent, target_is_directory=True)
    return queue.parent.parent / "linked" / "queue.db"


def hard_link(queue: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (queue.parent.parent / "elsewhere").mkdir()
    os.link(queue, queue.parent.parent / "elsewhere" / "other.db")
    return queue.parent.parent / "elsewhere" / "other.db"


NAMES: dict[str, Callable[[Path, pytest.MonkeyPatch], Path]] = {
    "relative": relative,
    "symlink to the file": symlink_to_file,
    "symlink to the folder": symlink_to_folder,
    "hard link": hard_link,
}


@pytest.fixture
def queue(tmp_path: Path) -> Path:
    return tmp_path / "data" / "queue.db"


@pytest.mark.parametrize("name", NAMES)
def test_every_name_of_the_file_meets_the_same_lock(
    queue: Path, name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    lock = ServiceLock(queue)
    try:
        alias = NAMES[name](queue, monkeypatch)
        with pytest.raises(QueueError) as refused:
            ServiceLock(alias)
        assert f"in use by another phytrace-edge run (pid {os.getpid()}) through {queue}" in str(
            refused.value
        )
    finally:
        lock.release()
    ServiceLock(alias).release()  # released: free again, by any name


def test_the_lock_says_who_holds_it_and_by_which_name(queue: Path) -> None:
    (queue.parent).mkdir()
    (queue.parent / "alias.db").symlink_to("queue.db")
    lock = ServiceLock(queue.parent / "alias.db")
    try:
        assert lock.path == Path(f"{queue}.lock")  # beside the file, not the symlink
        assert lock.path.read_text() == f"{os.getpid()}\n{queue.parent / 'alias.db'}\n"
    finally:
        lock.release()


def test_a_first_start_makes_a_private_folder_and_file_to_lock(queue: Path) -> None:
    lock = ServiceLock(queue)
    try:
        assert stat.S_IMODE(queue.parent.stat().st_mode) == 0o700
        assert stat.S_IMODE(queue.stat().st_mode) == 0o600 and queue.stat().st_size == 0
        os.link(queue, queue.parent / "later.db")  # a hard link made after the start
        with pytest.raises(QueueError, match="another name of this file"):
            ServiceLock(queue.parent / "later.db")
    finally:
        lock.release()


def test_what_is_not_a_regular_file_is_never_opened(queue: Path) -> None:
    """A FIFO would block an open; the store refuses it with its own line."""
    queue.parent.mkdir()
    os.mkfifo(queue)
    ServiceLock(queue).release()


def test_the_owners_of_one_file_are_found_by_any_name(
    queue: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    queue.parent.mkdir()
    queue.touch()
    owner = Owner(queue)
    try:
        for name in ("relative", "symlink to the file", "symlink to the folder"):
            alias = NAMES[name](queue, monkeypatch)
            other = Owner(alias)
            other.close()
            assert other.folder == owner.folder == Path(f"{queue}.owners")
            assert is_alive(alias, owner.token)
            assert dead_owners(alias, {f"{owner.token}:1"}, "another") == []
    finally:
        owner.close()
    assert dead_owners(queue.parent / "alias.db", {f"{owner.token}:1"}, "x") == [owner.token]
