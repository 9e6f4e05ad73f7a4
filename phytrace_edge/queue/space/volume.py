"""The volume under the queue: how much room it really has, and the effective cap.

A queue is bounded by QUEUE_MAX_BYTES and by the volume it lives on, whichever is
smaller. What the volume can give the queue is what the queue's files take now plus
what is free (``statvfs``), less the full-disk reserve (``reserve``) and a margin. Of
the smaller of the two, twice the WAL's share is kept for the WAL and for the pages a
transaction writes before it frees others (as ever for QUEUE_MAX_BYTES); the rest is
the **effective cap**: the bytes the queue's events may take. The caps (``caps``)
thin or drop to stay under it, so a small volume is thinned like a small
QUEUE_MAX_BYTES rather than filled up, and ``status`` judges the queue's fill by it.

A folder that cannot be looked at (moved, removed, unmounted) is "unknown", never an
error: the volume then sets no limit, and nothing is judged full by it.

Stdlib only: ``status`` reads it at start-up (``inspect``).
"""

import os
from typing import NamedTuple

MIB = 1024 * 1024
WAL_SHARE_MAX = 4 * MIB
MIN_RESERVE_BYTES = 256 * 1024
RESERVE_SHARE_OF_VOLUME = 16  # a small volume keeps a reserve of 1/16 of its size
MARGIN_MIN, MARGIN_MAX = 256 * 1024, 64 * MIB
MARGIN_SHARE_OF_VOLUME = 64
LIMIT_SETTING, LIMIT_VOLUME = "QUEUE_MAX_BYTES", "volume"


class Volume(NamedTuple):
    """A volume as ``statvfs`` saw it."""

    free: int  # bytes this user may still write (f_bavail)
    size: int  # bytes of the whole volume (f_blocks)


class Cap(NamedTuple):
    """The effective cap: what the queue's events may take, and which limit set it."""

    bytes: int  # database pages the events may use: ``files`` less twice the WAL's share
    limited_by: str  # LIMIT_SETTING (QUEUE_MAX_BYTES) or LIMIT_VOLUME
    files: int  # what the queue's database and WAL may take together


def look_at(folder: str | os.PathLike[str]) -> Volume | None:
    """The volume holding ``folder``; None when it cannot be looked at (the folder is
    gone, moved or unmounted): unknown, which is never "full"."""
    try:
        found = os.statvfs(folder)
    except OSError:
        return None
    return Volume(found.f_bavail * found.f_frsize, found.f_blocks * found.f_frsize)


def wal_share(cap_bytes: int) -> int:
    """The share of a cap kept for the WAL (SQLite's journal_size_limit)."""
    return min(WAL_SHARE_MAX, cap_bytes // 8)


def reserve_size(max_bytes: int, volume_size: int) -> int:
    """The full-disk reserve's size: the WAL's share of QUEUE_MAX_BYTES, less on a
    small volume (1/16 of it), at least 256 KiB."""
    share = volume_size // RESERVE_SHARE_OF_VOLUME
    return max(MIN_RESERVE_BYTES, min(wal_share(max_bytes), share))


def margin(volume_size: int) -> int:
    """Room left free on the volume beyond the reserve: 1/64 of it, 256 KiB to 64 MiB."""
    return min(MARGIN_MAX, max(MARGIN_MIN, volume_size // MARGIN_SHARE_OF_VOLUME))


def volume_room(queue_files: int, volume: Volume, max_bytes: int) -> int:
    """What the volume can give the queue's database and WAL: what the queue's files
    take now (``queue_files``, its reserve included) and what is free, less the
    reserve and the margin."""
    reserve = reserve_size(max_bytes, volume.size)
    return max(0, queue_files + volume.free - reserve - margin(volume.size))


def effective_cap(max_bytes: int, queue_files: int, volume: Volume | None) -> Cap:
    """QUEUE_MAX_BYTES, or what the volume can give the queue when that is less
    (``volume_room``); of it, what the events may take (twice the WAL's share is
    the WAL's)."""
    files, limited_by = max_bytes, LIMIT_SETTING
    if volume is not None:
        room = volume_room(queue_files, volume, max_bytes)
        if room < max_bytes:
            files, limited_by = room, LIMIT_VOLUME
    return Cap(max(0, files - 2 * wal_share(files)), limited_by, files)
