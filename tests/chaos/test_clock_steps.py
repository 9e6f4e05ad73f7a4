"""Chaos: the wall clock of a real bridge process steps, as NTP steps it on a robot
without a real-time clock. libfaketime fakes the wall clock only
(FAKETIME_DONT_FAKE_MONOTONIC=1), read from a file the test rewrites to step it; a
small preload shim hands monotonic sleeps to the kernel, which libfaketime 0.9.10 gets
wrong (Python's time.sleep fails with EINVAL). The queue file is real, PhyCloud is a
real stub process, down and then up on the same port."""

from __future__ import annotations

import shutil
import signal
import subprocess
import time
from datetime import datetime
from pathlib import Path

import pytest

from phytrace_edge.host_clock import synchronized
from phytrace_edge.queue.inspect import QueueStats, read_stats
from tests.processes import BridgeProcess, StubProcess, wait_for

Y2001 = 978_307_200  # 2001-01-01T00:00:00Z
LEASED_MAX = 40  # events the live and backfill lanes may hold in requests at the step
TWENTY_YEARS_S = 20 * 365 * 86_400

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


@pytest.fixture
def faked_clock(tmp_path: Path) -> tuple[dict[str, str], Path]:
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


def unix(captured_at: str) -> float:
    return datetime.fromisoformat(captured_at.replace("Z", "+00:00")).timestamp()


def stats(queue: Path) -> QueueStats:
    found = read_stats(str(queue))
    assert found is not None
    return found


@pytest.mark.timeout(300)  # waits for the service's minute-long maintenance pass
def test_a_step_from_2001_to_now_during_an_outage_loses_and_stalls_nothing(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path]
) -> None:
    env, offset_file = faked_clock
    set_wall_clock(offset_file, Y2001)
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db")  # its port chosen, not yet listening
    bridge = BridgeProcess(
        log,
        **env,
        PHYCLOUD_ENDPOINT=phycloud.endpoint,
        QUEUE_PATH=str(queue),
        BRIDGE_INPUT="sim",
        SAMPLE_RATE_HZ="20",
        FLUSH_INTERVAL_S="0.2",
        BATCH_SIZE="10",
        BACKLOG_BATCH_SIZE=str(LEASED_MAX // 2),  # what a retrying sender holds is not repaired
        RETRY_MIN_S="0.1",
        RETRY_MAX_S="1",
        LOG_LEVEL="debug",
    ).start()
    try:
        wait_for(lambda: queue.exists() and stats(queue).depth >= 100, 60, "events queued in 2001")
        assert stats(queue).oldest_queued_at is not None
        passes_before = log.read_text().count("queue maintenance pass done")
        queued_before_step = stats(queue).queued_total
        started_at = time.time()
        set_wall_clock(offset_file, started_at)  # NTP: 25 years forward
        wait_for(
            lambda: (stats(queue).clock.last_step_s or 0) > TWENTY_YEARS_S, 30, "the step seen"
        )
        # the backlog must live through a maintenance pass (TTL) on the new clock
        wait_for(
            lambda: log.read_text().count("queue maintenance pass done") > passes_before,
            120,
            "a maintenance pass after the step",
        )
        after_step = stats(queue)
        assert after_step.drops == {}, after_step.drops
        assert after_step.oldest_queued_at is not None
        assert after_step.read_at - after_step.oldest_queued_at < 600  # minutes, not years

        phycloud.start()  # PhyCloud is back
        wait_for(lambda: phycloud.stats()["received"] >= after_step.depth, 60, "the backlog sent")
        bridge.signal(signal.SIGTERM)
        assert bridge.wait(timeout=60) == 0
        final = stats(queue)
        sent = phycloud.stats()
        assert final.drops == {}
        assert final.queued_total == final.acked_total + final.depth
        assert sent["unique"] == sent["received"] == final.acked_total  # each exactly once
        assert "expired" not in log.read_text()
        if synchronized() is not False:
            return  # only stamps the kernel calls unsynchronized are marked and repaired
        stamps = [(unix(e["captured_at"]), e.get("wall_clock", {})) for e in phycloud.events()]
        in_2001 = [clock for at, clock in stamps if at < started_at - 3600]
        corrected = [at for at, clock in stamps if "corrected_by_s" in clock]
        # every event stamped in 2001 was repaired, unless a request held it at the step
        assert all(clock == {"synchronized": False} for clock in in_2001), in_2001[:3]
        assert len(in_2001) <= LEASED_MAX
        assert len(corrected) >= queued_before_step - LEASED_MAX
        assert all(at > started_at - 3600 for at in corrected)
    finally:
        bridge.stop()
        phycloud.stop()
