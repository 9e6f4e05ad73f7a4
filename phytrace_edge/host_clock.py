"""What the kernel says about this machine's clocks: which boot this is, and whether
the wall clock is synchronized. Read by the queue (queue time,
``queue/timekeeping/clock.py``) and by the builder's wiring (events stamped on an
unsynchronized clock say so)."""

from __future__ import annotations

import functools
import time
from typing import Any

BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"
SYNC_CACHE_S = 1.0  # the builder asks at every tick; the kernel's answer is kept a second


@functools.cache
def boot_id() -> str:
    """The kernel's id of this boot (a container sees its host's); a fixed stand-in
    where there is none, so such a machine counts every start as the same boot."""
    try:
        with open(BOOT_ID_PATH, encoding="ascii") as file:
            return file.read().strip()
    except OSError:
        return "unknown"


def synchronized() -> bool | None:
    """Whether the kernel says the wall clock is synchronized (``adjtimex`` without
    STA_UNSYNC, read the way ``ntp_gettime`` does); None where it will not say (a
    seccomp filter returning EPERM, as a container's may)."""
    try:
        adjtimex, timex = _adjtimex()
        state = adjtimex(timex)
    except (OSError, AttributeError):
        return None
    sta_unsync, time_error = 0x0040, 5
    if state == -1:
        return None
    return state != time_error and not timex._obj.status & sta_unsync


@functools.cache
def _adjtimex() -> tuple[Any, Any]:
    """libc's adjtimex and a ``struct timex`` to read into (modes 0: read only)."""
    import ctypes  # here: only the service and drain ask, never `status` at start-up

    class Timex(ctypes.Structure):  # struct timex up to `status`, then room for the rest
        _fields_ = [
            ("modes", ctypes.c_uint),
            ("offset", ctypes.c_long),
            ("freq", ctypes.c_long),
            ("maxerror", ctypes.c_long),
            ("esterror", ctypes.c_long),
            ("status", ctypes.c_int),
            ("rest", ctypes.c_byte * 256),
        ]

    libc = ctypes.CDLL(None, use_errno=True)
    return libc.adjtimex, ctypes.byref(Timex())


_last_answer = (float("-inf"), False)


def unsynchronized() -> bool:
    """The kernel says the wall clock is not synchronized (not merely "will not say"),
    asked at most once a second."""
    global _last_answer
    asked_at, answer = _last_answer
    if time.monotonic() - asked_at >= SYNC_CACHE_S:
        answer = synchronized() is False
        _last_answer = (time.monotonic(), answer)
    return answer
