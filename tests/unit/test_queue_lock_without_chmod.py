"""The service lock on a volume that refuses ``chmod`` (vfat, some FUSE and network
mounts): the queue file the lock makes at a first start keeps the mode its creation
gave it, and the lock is held all the same (queue/outbound/ownership.py)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.outbound.ownership import ServiceLock


def test_a_first_start_on_a_volume_that_refuses_chmod_still_takes_the_lock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``phytrace-edge run`` must start on such a volume, and a second run on the same
    file must still be stopped by the lock; a refused chmod escaping as an error would
    keep the bridge from starting at all."""

    def refuse(fd: int, mode: int) -> None:
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "fchmod", refuse)
    queue = tmp_path / "data" / "queue.db"
    lock = ServiceLock(queue)
    try:
        assert queue.is_file(), "the queue file was made, to be locked"
        with pytest.raises(QueueError, match="in use by another phytrace-edge run"):
            ServiceLock(queue)
    finally:
        lock.release()
    ServiceLock(queue).release()
