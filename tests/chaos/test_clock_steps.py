"""Chaos: the wall clock of a real bridge process steps, as NTP steps it on a robot
without a real-time clock. libfaketime fakes the wall clock only
(FAKETIME_DONT_FAKE_MONOTONIC=1), read from a file the test rewrites to step it; a
small preload shim hands monotonic sleeps to the kernel, which libfaketime 0.9.10 gets
wrong (Python's time.sleep fails with EINVAL). The queue file is real, PhyCloud is a
real stub process, down and then up on the same port."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from phytrace_edge.host_clock import synchronized
from phytrace_edge.udm.event import parse_timestamp
from tests.chaos.machine_time import (
    DAY_S,
    TWENTY_YEARS_S,
    Y2001,
    faked_bridge,
    heartbeat_after,
    queued,
    queued_up_to,
    set_wall_clock,
    stamps_at,
    stats,
    stopped_and_counted,
)
from tests.processes import StubProcess, status_json, wait_for


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
        found = stamps_at(phycloud, started_at)
        # PhyCloud was down at the step: no request got through, so all were repaired,
        # those the sender held and retried included. An event whose stamp was already
        # right needs no repair: once (CI of cf48fcd) one log record came stamped with
        # the real 2026 time among the 2001 ones, a clock read libfaketime did not fake
        assert found.old == []
        assert len(found.corrected) + len(found.right_before) >= before_step.queued_total
        assert len(found.corrected) >= before_step.queued_total - 2, found.right_before
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
            found = stamps_at(phycloud, stepped_at)
            sent_before_step = 20 + 2 * 20 + 10  # seen sent, then two requests and a live one
            assert len(found.old) <= sent_before_step + 50  # + what went out until the step
            assert len(found.corrected) >= 100
    finally:
        bridge.stop()
        phycloud.stop()


@pytest.mark.timeout(180)
def test_a_step_back_by_a_day_during_an_outage_stalls_nothing(
    tmp_path: Path, faked_clock: tuple[dict[str, str], Path]
) -> None:
    """The clock was a day ahead and steps back while PhyCloud is down: a lease or a
    schedule kept on the wall clock would now wait a day; the backlog must go at once."""
    env, offset_file = faked_clock
    set_wall_clock(offset_file, time.time() + DAY_S)
    queue, log = tmp_path / "queue.db", tmp_path / "bridge.log"
    phycloud = StubProcess(tmp_path / "stub.db")
    bridge = faked_bridge(env, log, queue, phycloud.endpoint)
    try:
        wait_for(lambda: queued(queue) >= 100, 60, "events queued a day ahead")
        before_step = stats(queue)
        stepped_at = time.time()
        set_wall_clock(offset_file, stepped_at)  # back by a day
        wait_for(lambda: (stats(queue).clock.last_step_s or 0) < -DAY_S + 60, 30, "the step seen")
        assert stats(queue).drops == {}
        phycloud.start()
        wait_for(lambda: not queued_up_to(queue, before_step.read_at), 60, "the backlog sent")
        stopped_and_counted(bridge, queue, phycloud)
        if synchronized() is not False:
            return
        stamps = [(parse_timestamp(e["captured_at"]), e["wall_clock"]) for e in phycloud.events()]
        ahead = [clock for at, clock in stamps if at > time.time() + 3600]
        corrected = [at for at, clock in stamps if "corrected_by_s" in clock]
        # an event already stamped right before the step needs no repair: under load,
        # libfaketime (reading its file at every call) once gave one read of the real
        # clock between two of the day-ahead one (CI, 2026-11-26: 15.986 between 15.812
        # and 16.190 corrected), as in the test from 2001 above
        right_before = [at for at, c in stamps if "corrected_by_s" not in c and at < stepped_at]
        assert ahead == []  # none left a day in the future
        assert len(corrected) + len(right_before) >= before_step.queued_total
        assert len(corrected) >= before_step.queued_total - 2, right_before
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
