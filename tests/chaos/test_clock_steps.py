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
from pathlib import Path

import pytest

from phytrace_edge.errors import QueueError
from phytrace_edge.host_clock import synchronized
from phytrace_edge.queue.inspect import QueueStats, read_stats
from phytrace_edge.udm.event import parse_timestamp
from tests.processes import BridgeProcess, StubProcess, status_json, wait_for

Y2001 = 978_307_200  # 2001-01-01T00:00:00Z
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


def faked_bridge(
    env: dict[str, str], log: Path, queue: Path, endpoint: str, **extra: str
) -> BridgeProcess:
    """``phytrace-edge run --input sim`` on the faked clock, started."""
    return BridgeProcess(
        log,
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


def stamps_at(phycloud: StubProcess, stepped_at: float) -> tuple[list[dict], list[float]]:
    """(the ``wall_clock`` of each event PhyCloud holds stamped before ``stepped_at``
    and not repaired, the repaired ones' stamps); every repaired stamp must be after
    it, and every unrepaired old one must say its clock was not synchronized."""
    stamps = [
        (parse_timestamp(e["captured_at"]), e.get("wall_clock", {})) for e in phycloud.events()
    ]
    old = [clock for at, clock in stamps if at < stepped_at - 3600]
    corrected = [at for at, clock in stamps if "corrected_by_s" in clock]
    assert all(clock == {"synchronized": False} for clock in old), old[:3]
    assert all(at > stepped_at - 3600 for at in corrected)
    return old, corrected


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


@pytest.mark.timeout(300)  # waits for the service's minute-long maintenance pass
def test_a_step_from_2001_to_now_during_an_outage_loses_and_stalls_nothing(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path]
) -> None:
    env, offset_file = faked_clock
    set_wall_clock(offset_file, Y2001)
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db")  # its port chosen, not yet listening
    bridge = faked_bridge(env, log, queue, phycloud.endpoint)
    try:
        wait_for(lambda: queued(queue) >= 100, 60, "events queued in 2001")
        assert stats(queue).oldest_queued_at is not None
        passes_before = log.read_text().count("queue maintenance pass done")
        before_step = stats(queue)
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
        # live data goes first: wait until no row queued before the step still waits
        wait_for(lambda: not queued_up_to(queue, before_step.read_at), 60, "the backlog sent")
        stopped_and_counted(bridge, queue, phycloud)
        assert "expired" not in log.read_text()
        if synchronized() is not False:
            return  # only stamps the kernel calls unsynchronized are marked and repaired
        in_2001, corrected = stamps_at(phycloud, started_at)
        # PhyCloud was down at the step: no request got through, so all were repaired,
        # those the sender held and retried included
        assert in_2001 == []
        assert len(corrected) >= before_step.queued_total
    finally:
        bridge.stop()
        phycloud.stop()


@pytest.mark.timeout(300)
def test_a_step_forward_by_years_during_a_drain_sends_each_event_once(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path]
) -> None:
    """The clock steps while a backlog drains through a slow PhyCloud: leases, the
    lanes and the health checks keep going on queue time."""
    env, offset_file = faked_clock
    set_wall_clock(offset_file, Y2001)
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db", "--latency", "0.2")
    # small requests, so that most of the backlog still waits in the queue at the step
    bridge = faked_bridge(env, log, queue, phycloud.endpoint, BACKLOG_BATCH_SIZE="20")
    try:
        wait_for(lambda: queued(queue) >= 200, 60, "a backlog in 2001")
        phycloud.start()
        wait_for(lambda: phycloud.stats()["received"] >= 20, 60, "the drain under way")
        stepped_at = time.time()
        set_wall_clock(offset_file, stepped_at)  # 25 years forward, mid-drain
        wait_for(
            lambda: (stats(queue).clock.last_step_s or 0) > TWENTY_YEARS_S, 30, "the step seen"
        )
        code, document = status_json(QUEUE_PATH=str(queue))
        assert document["running"], document  # the heartbeat's age did not jump
        assert code == 0, document["problems"]
        wait_for(lambda: stats(queue).depth < 20, 90, "the backlog drained after the step")
        final = stopped_and_counted(bridge, queue, phycloud)
        assert final.acked_total > 200
        if synchronized() is False:  # marked, so repaired: all but what was on the wire
            in_2001, corrected = stamps_at(phycloud, stepped_at)
            sent_before_step = 20 + 2 * 20 + 10  # seen sent, then two requests and a live one
            assert len(in_2001) <= sent_before_step + 50  # + what went out until the step
            assert len(corrected) >= 100
    finally:
        bridge.stop()
        phycloud.stop()


@pytest.mark.parametrize(
    "first_in_2001", [True, False], ids=["wrong-then-right", "right-then-wrong"]
)
def test_a_restart_onto_another_clock_keeps_ages_and_sends_each_event_once(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path], first_in_2001: bool
) -> None:
    """The queue is written under one wall clock and the next start (same boot: queue
    time goes on from the boot's base; across boots, tests/unit/test_queue_clock.py)
    has the other: its events are as old as the bridge was seen running, never years
    or less than nothing, and each reaches PhyCloud once."""
    env, offset_file = faked_clock
    set_wall_clock(offset_file, Y2001)
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db")
    first = faked_bridge(env if first_in_2001 else {}, log, queue, phycloud.endpoint)
    second = None
    try:
        wait_for(lambda: queued(queue) >= 50, 60, "events queued by the first start")
        first.signal(signal.SIGTERM)
        assert first.wait(timeout=60) == 0
        stopped_at = stats(queue).read_at
        second_env = {} if first_in_2001 else env
        second = faked_bridge(second_env, log, queue, phycloud.endpoint)
        wait_for(lambda: heartbeat_after(queue, stopped_at), 60, "the second start's heartbeat")
        # as the second start's clock sees it
        _, document = status_json(QUEUE_PATH=str(queue), **second_env)
        assert document["drops"] == {}
        assert 0 <= document["queue"]["oldest_age_s"] < 600  # minutes, not years
        phycloud.start()
        wait_for(lambda: stats(queue).acked_total >= 50, 60, "the first start's events sent")
        stopped_and_counted(second, queue, phycloud)
    finally:
        first.stop()
        if second is not None:
            second.stop()
        phycloud.stop()
