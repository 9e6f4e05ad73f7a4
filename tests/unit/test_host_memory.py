"""The C heap: its free pages go back to the kernel, and the service's threads share
two malloc arenas instead of one each."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from phytrace_edge.host_memory import MALLOC_ARENAS, _malloc_trim, limit_malloc_arenas

PEAK_THEN_TRIM = """
import gc
from phytrace_edge.host_memory import give_back_free_memory

def rss_mib():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 2**20

kept, freed = [], []
for n in range(20_000):  # 80 MB in malloc'd blocks, one in fifty kept: a fragmented heap
    (kept if n % 50 == 0 else freed).append(bytes(4000))
del freed
gc.collect()
before = rss_mib()
give_back_free_memory()
print(before - rss_mib())
"""


@pytest.mark.skipif(_malloc_trim() is None, reason="malloc_trim is glibc's")
def test_the_free_pages_of_a_fragmented_heap_go_back() -> None:
    result = subprocess.run(
        [sys.executable, "-c", PEAK_THEN_TRIM], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert float(result.stdout) > 40  # of about 78 MiB freed but still mapped


COUNT_ARENAS = """
import ctypes, sys, tempfile, threading
from phytrace_edge.host_memory import limit_malloc_arenas

if sys.argv[1] == "limit":
    assert limit_malloc_arenas({})
libc = ctypes.CDLL("libc.so.6")
libc.fopen.restype = ctypes.c_void_p
libc.fopen.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
libc.fclose.argtypes = [ctypes.c_void_p]
allocated, counted = threading.Barrier(7), threading.Barrier(7)
held = []

def work():
    held.append([bytes(4000) for _ in range(100)])  # malloc'd in this thread's arena
    allocated.wait()  # all six alive at once: no arena of an ended thread is reused
    counted.wait()

threads = [threading.Thread(target=work) for _ in range(6)]
for thread in threads:
    thread.start()
allocated.wait()
with tempfile.NamedTemporaryFile() as report:
    stream = libc.fopen(report.name.encode(), b"w")
    libc.malloc_info(0, stream)
    libc.fclose(stream)
    print(open(report.name).read().count("<heap nr="))
counted.wait()
for thread in threads:
    thread.join()
"""


def arenas_with_six_threads(mode: str) -> int:
    env = {key: value for key, value in os.environ.items() if key != "MALLOC_ARENA_MAX"}
    result = subprocess.run(
        [sys.executable, "-c", COUNT_ARENAS, mode],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert result.returncode == 0, result.stderr
    return int(result.stdout)


@pytest.mark.skipif(_malloc_trim() is None, reason="malloc arenas are glibc's")
def test_the_service_threads_share_two_malloc_arenas() -> None:
    assert arenas_with_six_threads("limit") <= MALLOC_ARENAS
    assert arenas_with_six_threads("glibc's default") == 7  # the main one, one per thread


def test_an_operators_own_arena_limit_is_left_alone() -> None:
    assert not limit_malloc_arenas({"MALLOC_ARENA_MAX": "4"})
