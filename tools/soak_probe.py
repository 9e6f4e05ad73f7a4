"""Run the bridge with a memory probe inside it: where a soak's RSS goes.

    python tools/soak_probe.py PROBE_FILE run --input sim

Runs ``phytrace-edge`` with the given arguments in this process, and every
``SOAK_PROBE_EVERY_S`` seconds (default 60) appends one JSON line to PROBE_FILE:

- ``python_mib``: the Python heap as ``tracemalloc`` traces it (objects, and the
  buffers Python allocates for them);
- ``malloc_used_mib`` / ``malloc_free_mib``: glibc's ``mallinfo2`` -- memory the C heap
  has handed out (Python's large objects, SQLite's page cache, zstd's contexts) and
  memory it holds free but mapped (fragmentation the next trim may or may not give back);
- ``top``: the ten source lines whose Python allocations grew most since the first probe
  (taken ``SOAK_PROBE_EVERY_S`` after the start, when the bridge is running).

If RSS rises while ``python_mib`` and ``malloc_used_mib`` stay flat, the rise is free heap
kept mapped; if ``malloc_used_mib`` rises, something below Python grows; if
``python_mib`` rises, ``top`` says where. Used by ``tools/soak_memory.py --probe``; a
tool, not part of the product (tracemalloc slows the bridge down).
"""

from __future__ import annotations

import ctypes
import json
import os
import sys
import threading
import time
import tracemalloc
from pathlib import Path

MIB = 1024 * 1024


class MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (glibc 2.33+), every field a size_t."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def c_heap() -> tuple[float, float]:
    """(MiB handed out, MiB free but mapped) of glibc's heap; (nan, nan) elsewhere."""
    try:
        mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return float("nan"), float("nan")
    mallinfo2.restype = MallInfo2
    info = mallinfo2()
    return (info.uordblks + info.hblkhd) / MIB, info.fordblks / MIB


def probe_forever(out: Path, every_s: float) -> None:
    started = time.monotonic()
    first = None  # the first probe's snapshot, once the bridge has started
    while True:
        time.sleep(every_s)  # a sampling period, not synchronisation
        snapshot = tracemalloc.take_snapshot()
        first = first or snapshot
        used, free = c_heap()
        top = snapshot.compare_to(first, "lineno")[:10]
        line = {
            "minutes": round((time.monotonic() - started) / 60, 2),
            "python_mib": round(tracemalloc.get_traced_memory()[0] / MIB, 2),
            "malloc_used_mib": round(used, 2),
            "malloc_free_mib": round(free, 2),
            "top": [f"{stat.size_diff / 1024:+.0f} KiB {stat.traceback[0]}" for stat in top],
        }
        with out.open("a") as probes:
            probes.write(json.dumps(line) + "\n")


def main() -> None:
    out, arguments = Path(sys.argv[1]), sys.argv[2:]
    tracemalloc.start(1)
    every_s = float(os.environ.get("SOAK_PROBE_EVERY_S", "60"))
    threading.Thread(target=probe_forever, args=(out, every_s), daemon=True).start()
    from phytrace_edge.cli import main as cli_main

    sys.exit(cli_main(arguments))


if __name__ == "__main__":
    main()
