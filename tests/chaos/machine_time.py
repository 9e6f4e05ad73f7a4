"""The machine's clocks, as the chaos tests change them for a real bridge process.

The wall clock: libfaketime fakes it only (FAKETIME_DONT_FAKE_MONOTONIC=1), read from
a file the test rewrites to step it, as NTP steps it on a robot without a real-time
clock; a small preload shim hands monotonic sleeps to the kernel, which libfaketime
0.9.10 gets wrong (Python's time.sleep fails with EINVAL).

A reboot: a ``Boot`` runs processes in a time namespace whose CLOCK_BOOTTIME and
CLOCK_MONOTONIC start near zero, and a mount namespace where
/proc/sys/kernel/random/boot_id reads a new id: the kernel's own clocks, as a process
sees them after a reboot (root only).
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any, NamedTuple

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.queue.peek import QueueStats, read_stats
from phytrace_edge.udm.event import parse_timestamp
from tests.processes import BridgeProcess, StubProcess, python_env

Y2001 = 978_307_200  # 2001-01-01T00:00:00Z
TWENTY_YEARS_S = 20 * 365 * 86_400
DAY_S = 86_400

SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <time.h>
#include <unistd.h>
#include <sys/syscall.h>

/* monotonic sleeps straight to the kernel; the others to libfaketime */
int clock_nanosleep(clockid_t id, int flags, const struct timespec *t, struct timespec *rem) {
    if (id == CLOCK_MONOTONIC || id == CLOCK_BOOTTIME)
        return syscall(SYS_clock_nanosleep, id, flags, t, rem) == -1 ? errno : 0;
    int (*next)(clockid_t, int, const struct timespec *, struct timespec *) =
        dlsym(RTLD_NEXT, "clock_nanosleep");
    return next(id, flags, t, rem);
}
"""


def faketime_env(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """(the environment that fakes a process's wall clock, the file that sets it)."""
    libraries = [str(p) for p in Path("/usr/lib").glob("*/faketime/libfaketime.so.1")]
    if not libraries or not shutil.which("gcc"):
        pytest.skip("needs libfaketime (Debian: faketime) and gcc; .ci/run installs them")
    shim = tmp_path / "monotonic_sleep.so"
    source = tmp_path / "monotonic_sleep.c"
    source.write_text(SHIM)
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", shim, source, "-ldl"], check=True)
    offset = tmp_path / "faketime"
    env = {
        "LD_PRELOAD": f"{shim}:{libraries[0]}",
        "FAKETIME_TIMESTAMP_FILE": str(offset),
        "FAKETIME_NO_CACHE": "1",
        "FAKETIME_DONT_FAKE_MONOTONIC": "1",
    }
    return env, offset


def set_wall_clock(offset_file: Path, unix_s: float) -> None:
    """Step the faked wall clock to ``unix_s`` (an offset from the real one)."""
    offset_file.write_text(f"{round(unix_s - time.time()):+d}\n")


def faked_bridge(
    env: dict[str, str],
    log: Path,
    queue: Path,
    endpoint: str,
    boot: Boot | None = None,
    **extra: str,
) -> BridgeProcess:
    """``phytrace-edge run --input sim`` on the faked clock (and in ``boot``), started."""
    return BridgeProcess(
        log,
        preexec=boot.enter if boot is not None else None,
        **env,
        **extra,
        PHYCLOUD_ENDPOINT=endpoint,
        QUEUE_PATH=str(queue),
        BRIDGE_INPUT="sim",
        SAMPLE_RATE_HZ="20",
        FLUSH_INTERVAL_S="0.2",
        BATCH_SIZE="10",
        RETRY_MIN_S="0.1",
        RETRY_MAX_S="1",
        LOG_LEVEL="debug",
    ).start()


def stopped_and_counted(bridge: BridgeProcess, queue: Path, phycloud: StubProcess) -> QueueStats:
    """Stop the bridge (SIGTERM); check every event queued was delivered exactly once or
    still waits, and none was dropped; the final stats."""
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=60) == 0
    final = stats(queue)
    sent = phycloud.stats()
    assert final.drops == {}
    assert final.queued_total == final.acked_total + final.depth
    assert sent["unique"] == sent["received"] == final.acked_total  # each exactly once
    return final


class Stamps(NamedTuple):
    """The events PhyCloud holds, by how their ``captured_at`` relates to a step."""

    old: list[dict]  # the wall_clock of each stamped on the old clock and not repaired
    corrected: list[float]  # the repaired stamps
    right_before: list[float]  # not repaired, already right, from before the step


def stamps_at(phycloud: StubProcess, stepped_at: float) -> Stamps:
    """The events' stamps around a step at ``stepped_at``; every repaired stamp must be
    after the old clock's time, and every unrepaired old one must say its clock was
    not synchronized."""
    stamps = [
        (parse_timestamp(e["captured_at"]), e.get("wall_clock", {})) for e in phycloud.events()
    ]
    old = [clock for at, clock in stamps if at < stepped_at - 3600]
    corrected = [at for at, clock in stamps if "corrected_by_s" in clock]
    right_before = [
        at
        for at, clock in stamps
        if stepped_at - 3600 <= at < stepped_at and "corrected_by_s" not in clock
    ]
    assert all(clock == {"synchronized": False} for clock in old), old[:3]
    assert all(at > stepped_at - 3600 for at in corrected)
    return Stamps(old, corrected, right_before)


def queued(queue: Path) -> int:
    """Events waiting; 0 while the service is still creating the queue."""
    try:
        found = read_stats(str(queue))
    except QueueError:  # the file exists, its tables not yet
        return 0
    return 0 if found is None else found.depth


def queued_up_to(queue: Path, queue_time: float) -> bool:
    """Whether a row queued at or before ``queue_time`` still waits."""
    oldest = stats(queue).oldest_queued_at
    return oldest is not None and oldest <= queue_time


def heartbeat_after(queue: Path, at: float) -> bool:
    service = stats(queue).service
    return service is not None and service.running and service.heartbeat_at > at


def stats(queue: Path) -> QueueStats:
    found = read_stats(str(queue))
    assert found is not None
    return found


CLONE_NEWNS = 0x00020000
CLONE_NEWTIME = 0x00000080
MS_BIND, MS_REC, MS_PRIVATE = 0x1000, 0x4000, 0x40000
BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"


class Boot:
    """A boot of the machine as the processes started in it see it: its own boot id,
    and CLOCK_BOOTTIME/CLOCK_MONOTONIC counting from ``booted_at`` (the kernel's
    clocks, moved by a time namespace). Processes run in it with
    ``preexec_fn=boot.enter``."""

    def __init__(self, folder: Path, booted_at: float) -> None:
        if os.geteuid() != 0:
            pytest.skip("a reboot needs root: time and mount namespaces")
        self.boot_id = str(uuid.uuid4())
        self.id_file = folder / f"boot_id-{self.boot_id}"
        self.id_file.write_text(self.boot_id + "\n")
        # one offset for every process of this boot: its clocks go on together
        uptime = time.time() - booted_at
        offset_ns = round((uptime - time.clock_gettime(time.CLOCK_BOOTTIME)) * 1e9)
        self.offset = divmod(offset_ns, 1_000_000_000)  # (seconds, 0 <= nanoseconds)

    def enter(self) -> None:
        """In the child between fork and exec: a time namespace (entered at exec) with
        this boot's offsets, and a private mount namespace where the boot id is ours."""
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.unshare(CLONE_NEWTIME | CLONE_NEWNS) != 0:
            raise OSError(ctypes.get_errno(), "unshare(CLONE_NEWTIME | CLONE_NEWNS)")
        with Path("/proc/self/timens_offsets").open("w") as offsets:
            seconds, nanoseconds = self.offset
            offsets.write(f"boottime {seconds} {nanoseconds}\nmonotonic {seconds} {nanoseconds}\n")
        # private first: a bind mount must not reach the machine's own namespace
        if libc.mount(None, b"/", None, MS_REC | MS_PRIVATE, None) != 0:
            raise OSError(ctypes.get_errno(), "mount --make-rprivate /")
        if libc.mount(str(self.id_file).encode(), BOOT_ID_PATH.encode(), None, MS_BIND, None):
            raise OSError(ctypes.get_errno(), f"mount --bind over {BOOT_ID_PATH}")

    def status(self, queue: Path, **env: str) -> tuple[int, dict[str, Any]]:
        """``phytrace-edge status --json`` in this boot: (exit code, document)."""
        result = subprocess.run(
            [sys.executable, "-m", "phytrace_edge", "status", "--json"],
            capture_output=True,
            text=True,
            timeout=60,
            env=python_env(QUEUE_PATH=str(queue), **env),
            preexec_fn=self.enter,
        )
        return result.returncode, json.loads(result.stdout) if result.stdout else {}
