"""Spare room for a full disk: a file of reserved bytes beside the queue.

When the filesystem is full, SQLite cannot even delete: a delete writes pages to the
WAL, and moving the WAL back into the database may have to grow the file. So a full
disk would leave the bridge unable to ack what PhyCloud accepted, drop the oldest
events, or take a claim, and it would never recover by itself. The queue therefore
keeps ``<queue>-reserve``, a few MiB it gives up the first time a write fails for lack
of space; that lets deletes and claims go on, and the pages they free hold new events
again. The reserve is made again as soon as the disk has room for it twice over
(``full_disk``: looked at on the put path, at most once a second, and by maintenance).

Nothing here raises for a folder that is gone (moved, removed, unmounted): the reserve
is then simply not held, and cannot be made.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

from phytrace_edge.durable import sync_folder
from phytrace_edge.queue.space.volume import (
    MIN_RESERVE_BYTES,
    RESERVE_SHARE_OF_VOLUME,
    effective_cap,
    look_at,
    volume_room,
)
from phytrace_edge.units import format_bytes

log = logging.getLogger(__name__)

RESERVE_SUFFIX = "-reserve"


class SpaceReserve:
    def __init__(self, queue_path: Path, size: int) -> None:
        self.path = Path(f"{queue_path}{RESERVE_SUFFIX}")
        self.size = size
        # given up for a full disk, or not made for lack of room, and not made since
        self.lacked_room = False

    @classmethod
    def sized_for(cls, queue_path: Path, at_most: int) -> SpaceReserve:
        """A reserve of ``at_most`` bytes, less on a small volume (1/16 of it)."""
        volume = look_at(queue_path.parent)
        share = at_most if volume is None else volume.size // RESERVE_SHARE_OF_VOLUME
        return cls(queue_path, max(MIN_RESERVE_BYTES, min(at_most, share)))

    def held(self) -> bool:
        """Whether the reserve is there at its full size: a power cut right after it
        was made can leave the file empty, which holds nothing."""
        try:
            return self.path.stat().st_size >= self.size
        except OSError:  # not there, or its folder is gone
            return False

    def restore(self) -> bool:
        """Make the reserve when it is missing or short and the disk has room for it
        twice; it is synced, file and folder, so that a power cut keeps it. False when
        it could not be made (no room, or the folder is gone)."""
        if self.held():
            return True
        volume = look_at(self.path.parent)
        if volume is None:
            return False
        if volume.free < 2 * self.size:
            self.lacked_room = True
            return False
        try:
            self.path.unlink(missing_ok=True)  # a short one, left by a power cut
            descriptor = os.open(self.path, os.O_CREAT | os.O_WRONLY | os.O_EXCL, 0o600)
        except FileExistsError:
            return True
        except OSError:
            return False
        try:
            os.posix_fallocate(descriptor, 0, self.size)  # real blocks, not a sparse file
            os.fsync(descriptor)
        except OSError:
            os.close(descriptor)
            with contextlib.suppress(OSError):
                self.path.unlink()
            return False
        os.close(descriptor)
        try:
            sync_folder(self.path.parent)
        except OSError:
            return False
        self.lacked_room = False
        return True

    def release(self) -> bool:
        """Give the reserve back to the filesystem; False when there was none."""
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
            self.lacked_room = True
            log.error(
                "queue %s: the disk is full; released the queue's %s reserve so that it can "
                "still delete and claim events - free space on the volume",
                self.path.with_name(self.path.name.removesuffix(RESERVE_SUFFIX)),
                format_bytes(self.size),
            )
            return True
        return False


def warn_if_volume_smaller_than(queue_path: Path, queue_bytes: int, max_bytes: int) -> None:
    """Log a WARNING when the volume could not hold a queue of ``max_bytes``: the
    volume is then the queue's cap (``volume``)."""
    volume = look_at(queue_path.parent)
    if volume is None:
        return
    room = volume_room(queue_bytes, volume, max_bytes)
    if room < max_bytes:
        log.warning(
            "queue %s: the volume has room for %s of queue, less than QUEUE_MAX_BYTES "
            "(%s): the volume is the cap (events may take %s), and QUEUE_ON_FULL applies "
            "when it is reached - free space or lower QUEUE_MAX_BYTES",
            queue_path,
            format_bytes(room),
            format_bytes(max_bytes),
            format_bytes(effective_cap(max_bytes, queue_bytes, volume).bytes),
        )
