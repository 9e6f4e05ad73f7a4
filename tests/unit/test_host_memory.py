"""The C heap's free pages go back to the kernel after start-up's one-off peak."""

from __future__ import annotations

import subprocess
import sys

import pytest

from phytrace_edge.host_memory import _malloc_trim

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
