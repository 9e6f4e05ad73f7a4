"""Chaos: the robot loses power and boots again between two runs of the bridge, on the
kernel's own clocks: the second run has a new boot id and CLOCK_BOOTTIME starting near
zero (``machine_time.Boot``: time and mount namespaces), and, on a robot without a
real-time clock, a wall clock back in 2001 that NTP later steps. Across boots, an event
is never older than it could be (docs/queue.md, "Time"); the stamps of the earlier
boot are left as they were, those of the new one before the step are repaired."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from phytrace_edge.host_clock import synchronized
from phytrace_edge.udm.event import parse_timestamp
from tests.chaos.machine_time import (
    TWENTY_YEARS_S,
    Y2001,
    Boot,
    faked_bridge,
    queued,
    queued_up_to,
    set_wall_clock,
    stats,
    stopped_and_counted,
)
from tests.processes import StubProcess, wait_for


@pytest.mark.timeout(240)
@pytest.mark.parametrize("rtc", [True, False], ids=["with-rtc", "without-rtc"])
def test_a_power_cut_and_a_reboot_keep_ages_true_and_send_each_event_once(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path], rtc: bool
) -> None:
    env, offset_file = faked_clock
    set_wall_clock(offset_file, time.time())  # right, in the first boot
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db")  # down until the end
    first_started = time.time()
    first = faked_bridge(
        env, log, queue, phycloud.endpoint, boot=Boot(tmp_path, booted_at=time.time() - 3600)
    )
    second = None
    try:
        wait_for(lambda: queued(queue) >= 50, 60, "events queued in the first boot")
        first.signal(signal.SIGKILL)  # the power goes
        first.wait(timeout=30)
        cut_at = time.time()
        before_cut = stats(queue)
        if not rtc:
            set_wall_clock(offset_file, Y2001)  # the next boot starts without a real-time clock
        boot = Boot(tmp_path, booted_at=cut_at)  # up again at once
        second = faked_bridge(env, log, queue, phycloud.endpoint, boot=boot)
        wait_for(
            lambda: stats(queue).queued_total > before_cut.queued_total + 20,
            60,
            "events queued in the second boot",
        )
        _, document = boot.status(queue, **env)  # as the new boot sees it
        assert document["running"], document
        assert document["drops"] == {}
        oldest_age = document["queue"]["oldest_age_s"]
        assert 0 <= oldest_age <= time.time() - first_started  # never older than it could be
        if not rtc:
            stepped_at = time.time()
            set_wall_clock(offset_file, stepped_at)  # NTP, in the second boot
            wait_for(
                lambda: (
                    (boot.status(queue, **env)[1]["clock"]["last_step_s"] or 0) > TWENTY_YEARS_S
                ),
                30,
                "the step seen",
            )
        phycloud.start()
        wait_for(
            lambda: not queued_up_to(queue, before_cut.newest_queued_at or 0),
            60,
            "the first boot's events sent",
        )
        stopped_and_counted(second, queue, phycloud)
        stamps = [(parse_timestamp(e["captured_at"]), e) for e in phycloud.events()]
        first_boot = [e for at, e in stamps if first_started - 2 <= at <= cut_at]
        assert len(first_boot) >= before_cut.queued_total
        assert not any("corrected_by_s" in e.get("wall_clock", {}) for e in first_boot)
        if not rtc and synchronized() is False:  # the second boot's 2001 stamps repaired
            assert [at for at, e in stamps if at < cut_at - 3600] == []
            corrected = [at for at, e in stamps if "corrected_by_s" in e.get("wall_clock", {})]
            assert corrected
            assert all(cut_at <= at <= stepped_at + 2 for at in corrected)
    finally:
        first.stop()
        if second is not None:
            second.stop()
        phycloud.stop()
