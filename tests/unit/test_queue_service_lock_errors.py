"""The service lock's refusals (``queue/outbound/ownership.py``), as the operator reads
them: a second ``run`` on a queue whose holder wrote only its pid (an older version),
or nothing yet, is refused with one line naming the pid; a queue whose folder cannot
hold the lock file is one line naming the queue. (Who holds it by which name:
test_queue_ownership.py.)"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.outbound.ownership import ServiceLock


@pytest.mark.parametrize(
    ("written", "pid"),
    [("4242\n", "4242"), ("", "?")],
    ids=["an older version wrote only its pid", "the holder has not written yet"],
)
def test_a_second_run_is_refused_with_the_pid_the_holder_wrote(
    tmp_path: Path, written: str, pid: str
) -> None:
    """Upgraded beside a running older bridge, or started in the instant after another
    took the lock: the refusal still says which pid holds the queue, in one line,
    instead of a crash with a traceback."""
    queue = tmp_path / "queue.db"
    lock_file = Path(f"{queue}.lock")
    lock_file.write_text(written)
    holder = os.open(lock_file, os.O_RDWR)
    try:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(QueueError) as refused:
            ServiceLock(queue)
    finally:
        os.close(holder)
    assert str(refused.value) == (
        f"queue {queue} is in use by another phytrace-edge run (pid {pid}) - stop that one "
        "first, or set QUEUE_PATH to another file"
    )


def test_a_queue_whose_folder_is_a_file_cannot_be_locked_and_says_so(tmp_path: Path) -> None:
    """QUEUE_PATH under a regular file (the queue file taken for its folder): ``run``
    stops with one line naming the queue and the cause, not a bare "None"."""
    (tmp_path / "queue.db").write_bytes(b"")
    queue = tmp_path / "queue.db" / "queue.db"
    with pytest.raises(QueueError) as refused:
        ServiceLock(queue)
    assert str(refused.value) == (
        f"queue {queue}: cannot lock it ({os.strerror(errno.EEXIST)}) - the queue's folder "
        "must be writable by the bridge"
    )
