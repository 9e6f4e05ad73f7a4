"""The C heap, kept small: fewer malloc arenas, and free memory handed back to the system."""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable, Mapping
from typing import Any

M_ARENA_MAX = -8  # mallopt's parameter number for the arena limit (glibc's malloc.h)
# glibc gives each new thread a heap ("arena") of its own, up to eight per core. Free
# memory is kept per arena, so the bridge's threads each hold the high-water mark of
# their own largest work (a drained backlog's batches) and the next trim cannot give
# back a page another block still touches. Two arenas keep 3-6 MiB less mapped over a
# soak (docs/benchmarks.md, "Memory soak"); the bridge's threads allocate mostly under
# the GIL, so they hardly contend for them.
MALLOC_ARENAS = 2


@functools.cache
def _libc(name: str) -> Callable[..., Any] | None:
    try:
        function: Callable[..., Any] = getattr(ctypes.CDLL("libc.so.6"), name)
        return function
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to tune
        return None


def _malloc_trim() -> Callable[..., Any] | None:
    return _libc("malloc_trim")


def limit_malloc_arenas(env: Mapping[str, str], arenas: int = MALLOC_ARENAS) -> bool:
    """Cap glibc's malloc arenas at ``arenas``, before the service starts its threads.
    An operator's own ``MALLOC_ARENA_MAX`` (which glibc read at start) is left as it
    is. Whether the limit was set."""
    mallopt = _libc("mallopt")
    if mallopt is None or "MALLOC_ARENA_MAX" in env:
        return False
    return bool(mallopt(M_ARENA_MAX, arenas))


def give_back_free_memory() -> None:
    """Return the free pages of the C heap to the kernel (glibc's ``malloc_trim``).
    Python frees what start-up needed only once, but glibc keeps the pages mapped; a
    service that runs for months never needs them again; after each maintenance pass
    too, for the buffers of a drained backlog (docs/benchmarks.md, "Footprint")."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
