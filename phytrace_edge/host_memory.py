"""Handing the C heap's free memory back to the system after start-up's one-off peak."""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    try:
        trim: Callable[[int], int] = ctypes.CDLL("libc.so.6").malloc_trim
        return trim
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to trim
        return None


def give_back_free_memory() -> None:
    """Return the free pages of the C heap to the kernel (glibc's ``malloc_trim``).
    Python frees what start-up needed only once, compiling the UDM validator above all
    (some 25 MiB), but glibc keeps the pages mapped; a service that runs for months
    never needs them again; after each maintenance pass too, for the buffers of a
    drained backlog (docs/benchmarks.md, "Footprint")."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
