"""Spare room for a full disk: a file of reserved bytes beside the queue.

When the filesystem is full, SQLite cannot even delete: a delete writes pages to the
WAL, and moving the WAL back into the database may have to grow the file. So a full
disk would leave the bridge unable to ack what PhyCloud accepted, drop the oldest
events, or take a claim, and it would never recover by itself. The queue therefore
keeps ``<queue>-reserve``, a few MiB it gives up the first time a write fails for lack
of space; that lets deletes and claims go on, and the pages they free hold new events
again. The reserve is made again once the disk has room for it twice over.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

from phytrace_edge.durable import sync_folder
from phytrace_edge.units import format_bytes

log = logging.getLogger(__name__)

RESERVE_SUFFIX = "-reserve"
MIN_RESERVE_BYTES = 256 * 1024
SHARE_OF_VOLUME = 16  # a small volume keeps a reserve of 1/16 of its size


class SpaceReserve:
    def __init__(self, queue_path: Path, size: int) -> None:
        self.path = Path(f"{queue_path}{RESERVE_SUFFIX}")
        self.size = size

    @classmethod
    def sized_for(cls, queue_path: Path, at_most: int) -> SpaceReserve:
        """A reserve of ``at_most`` bytes, less on a small volume."""
        volume = os.statvfs(queue_path.parent)
        share = volume.f_blocks * volume.f_frsize // SHARE_OF_VOLUME
        return cls(queue_path, max(MIN_RESERVE_BYTES, min(at_most, share)))

    def held(self) -> bool:
        """Whether the reserve is there at its full size: a power cut right after it
        was made can leave the file empty, which holds nothing."""
        try:
            return self.path.stat().st_size >= self.size
        except FileNotFoundError:
            return False

    def restore(self) -> bool:
        """Make the reserve when it is missing or short and the disk has room for it
        twice; it is synced, file and folder, so that a power cut keeps it."""
        if self.held():
            return True
        free = os.statvfs(self.path.parent)
        if free.f_bavail * free.f_frsize < 2 * self.size:
            return False
        self.path.unlink(missing_ok=True)  # a short one, left by a power cut
        try:
            descriptor = os.open(self.path, os.O_CREAT | os.O_WRONLY | os.O_EXCL, 0o600)
        except FileExistsError:
            return True
        try:
            os.posix_fallocate(descriptor, 0, self.size)  # real blocks, not a sparse file
            os.fsync(descriptor)
        except OSError:
            os.close(descriptor)
            self.path.unlink()
            return False
        os.close(descriptor)
        sync_folder(self.path.parent)
        return True

    def release(self) -> bool:
        """Give the reserve back to the filesystem; False when there was none."""
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
            log.error(
                "queue %s: the disk is full; released the queue's %s reserve so that it can "
                "still delete and claim events - free space on the volume",
                self.path.with_name(self.path.name.removesuffix(RESERVE_SUFFIX)),
                format_bytes(self.size),
            )
            return True
        return False


def warn_if_volume_smaller_than(queue_path: Path, queue_bytes: int, max_bytes: int) -> None:
    """Log a WARNING when the volume could not hold a queue of ``max_bytes``."""
    free = os.statvfs(queue_path.parent)
    available = free.f_bavail * free.f_frsize + queue_bytes
    if available < max_bytes:
        log.warning(
            "queue %s: the volume has %s free for the queue but QUEUE_MAX_BYTES is %s; "
            "the disk will fill before the cap - lower QUEUE_MAX_BYTES or free space",
            queue_path,
            format_bytes(available),
            format_bytes(max_bytes),
        )
