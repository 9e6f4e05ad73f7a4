"""Queue time on real SQLite files, with the machine's clocks stood in for: the wall
clock steps (forward by years, back by a day) while events wait and across reboots,
and no event is expired, no lease runs out, and no count moves because of it.
(tests/chaos/test_clock_steps.py does the same with real processes under libfaketime.)"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import pytest

from phytrace_edge.queue.clock import Instant, LastSeen, boot_base, synchronized
from phytrace_edge.queue.inspect import read_stats
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.runtime.health import Thresholds, report
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.units import MIB
from tests.unit.queue_fixtures import event, seqs

Y2001 = 978_307_200.0  # 2001-01-01T00:00:00Z: where a Raspberry Pi without RTC starts
NOW = 1_795_000_000.0  # late 2026
DAY = 86_400.0
TTL = QueueLimits(max_bytes=64 * MIB, ttl_s=7 * DAY)


@dataclass
class Machine:
    """A machine's clocks: a wall clock that steps, CLOCK_BOOTTIME that does not."""

    wall: float
    since_boot: float = 12.0
    boot_id: str = "boot-1"
    synchronized: bool = False

    def read(self) -> Instant:
        return Instant(self.wall, self.since_boot, self.boot_id, self.synchronized)

    def run(self, seconds: float) -> None:
        self.wall += seconds
        self.since_boot += seconds

    def reboot(self, off_for: float, wall: float, synchronized: bool) -> None:
        """Off for a while, then up again with the wall clock at ``wall``."""
        self.boot_id = f"{self.boot_id}+"
        self.since_boot = 8.0
        self.wall = wall
        self.synchronized = synchronized
        del off_for  # CLOCK_BOOTTIME starts again: the time off is what the clocks hide


def open_store(path: Path, machine: Machine) -> QueueStore:
    return QueueStore.open(path, limits=TTL, clocks=machine, lease_s=140)  # type: ignore[arg-type]


def test_boot_base_starts_a_new_queue_at_the_wall_clock() -> None:
    assert boot_base(Instant(NOW, 30.0, "b", False), None) == NOW - 30.0


@pytest.mark.parametrize(
    ("then_synchronized", "now_synchronized", "passed"),
    [(True, True, 3600.0), (True, False, 10.0), (False, True, 10.0), (False, False, 10.0)],
)
def test_time_off_counts_only_when_both_wall_clocks_were_true(
    then_synchronized: bool, now_synchronized: bool, passed: float
) -> None:
    """Else only the new boot's uptime (10 s) is sure to have passed."""
    last = LastSeen(queue_time=5000.0, wall=NOW, synchronized=then_synchronized)
    now = Instant(NOW + 3600.0, 10.0, "b2", now_synchronized)
    assert boot_base(now, last) + now.since_boot == 5000.0 + passed


def test_a_wall_clock_set_back_while_off_never_makes_time_run_back() -> None:
    last = LastSeen(queue_time=5000.0, wall=NOW, synchronized=True)
    now = Instant(NOW - DAY, 10.0, "b2", True)
    assert boot_base(now, last) + now.since_boot == 5010.0


def test_a_forward_step_expires_nothing_and_keeps_leases(tmp_path: Path) -> None:
    """The case found under libfaketime: a start at 2001, events queued, the clock
    stepped to the present, PhyCloud still down."""
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    store.put_many([event(i) for i in range(5)])
    sending = store.claim_batch(2, MIB)
    machine.run(30.0)
    machine.wall, machine.synchronized = NOW, True  # NTP steps the clock by 25 years
    assert store.record_clocks() == pytest.approx(NOW - Y2001 - 30.0)
    machine.run(30.0)
    store.maintain()
    stats = store.stats()
    assert stats.drops == {}
    assert stats.depth == 5
    assert store.claim_batch(10, MIB) is not None  # the three not being sent
    assert store.renew(sending)  # the lease taken before the step still holds
    assert stats.clock.last_step_s == pytest.approx(NOW - Y2001 - 30.0)
    assert stats.clock.synchronized is True
    store.close()


def test_a_backward_step_keeps_the_ttl_running(tmp_path: Path) -> None:
    machine = Machine(wall=NOW)
    store = open_store(tmp_path / "q.db", machine)
    store.put_many([event(i) for i in range(3)])
    machine.run(6 * DAY)
    machine.wall -= DAY  # set back a day
    assert store.record_clocks() == pytest.approx(-DAY)
    machine.run(DAY + 60.0)  # 7 days and a minute after the put, by a clock that does not step
    assert store.expire() == 3
    assert store.stats().drops == {"ttl": 3}
    store.close()


def test_a_queue_written_under_a_wrong_clock_survives_a_reboot_onto_the_right_one(
    tmp_path: Path,
) -> None:
    """2001 on the first boot (never synchronized), the present on the next: the events
    are as old as the time the machine was seen running, not 25 years."""
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    store.put_many([event(i) for i in range(4)])
    machine.run(120.0)
    store.maintain()
    store.close()
    machine.reboot(off_for=3 * DAY, wall=NOW, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    store.maintain()
    stats = store.stats()
    assert stats.drops == {}
    assert stats.oldest_queued_at is not None
    assert store.now() - stats.oldest_queued_at == pytest.approx(128.0)
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2, 3]
    store.close()


def test_time_off_counts_when_the_clock_was_true_before_and_after(tmp_path: Path) -> None:
    machine = Machine(wall=NOW, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    store.put_many([event(i) for i in range(2)])
    store.maintain()
    store.close()
    machine.reboot(off_for=8 * DAY, wall=NOW + 8 * DAY, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    assert store.expire() == 2  # really 8 days old: the TTL is 7
    store.close()


def test_the_reverse_a_right_clock_then_a_wrong_one(tmp_path: Path) -> None:
    machine = Machine(wall=NOW, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    store.put_many([event(i) for i in range(2)])
    store.maintain()
    store.close()
    machine.reboot(off_for=60.0, wall=Y2001, synchronized=False)
    store = open_store(tmp_path / "q.db", machine)
    machine.run(30.0)
    assert store.expire() == 0
    assert store.now() - store.stats().oldest_queued_at == pytest.approx(38.0)
    batch = store.claim_batch(10, MIB)
    machine.run(100.0)
    assert store.claim_batch(10, MIB) is None  # still leased: 100 s < 140 s
    store.ack(batch)
    stats = store.stats()
    assert (stats.depth, stats.acked_total, stats.drops) == (0, 2, {})
    store.close()


def test_every_process_of_a_boot_reads_the_same_queue_time(tmp_path: Path) -> None:
    machine = Machine(wall=Y2001)
    first = open_store(tmp_path / "q.db", machine)
    machine.run(10.0)
    machine.wall = NOW  # stepped before the second process opened
    second = open_store(tmp_path / "q.db", machine)
    assert first.now() == second.now()
    first.close()
    second.close()


def test_status_reads_ages_and_dates_on_queue_time(tmp_path: Path) -> None:
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    store.put(event(1))
    machine.run(50.0)
    machine.wall, machine.synchronized = NOW, True
    store.maintain()
    stats = store.stats()
    document = report(stats, Thresholds(10.0, 300.0, 0.8, TTL.max_bytes), stats.read_at)
    assert document["queue"]["oldest_age_s"] == pytest.approx(50.0)
    assert document["clock"]["synchronized"] is True
    assert document["clock"]["last_step_s"] == pytest.approx(NOW - Y2001 - 50.0)
    assert document["clock"]["last_step_at"] == format_timestamp(NOW)  # today's date, not 2001
    store.close()


def test_status_from_another_process_reads_the_same_queue_time(tmp_path: Path) -> None:
    """``read_stats`` (what ``status`` runs) takes this boot's base from the file."""
    store = QueueStore.open(tmp_path / "q.db", limits=TTL)
    store.put(event(1))
    before = store.now()
    stats = read_stats(str(tmp_path / "q.db"))
    after = store.now()
    assert stats is not None
    assert before <= stats.read_at <= after
    store.close()


def test_the_kernel_is_asked_whether_the_clock_is_synchronized() -> None:
    """Against ntp_gettime(3), another door to the same kernel state: TIME_ERROR (5)
    when the clock is not synchronized."""
    libc = ctypes.CDLL(None)
    buffer = ctypes.create_string_buffer(512)
    state = libc.ntp_gettime(buffer)
    assert synchronized() is (state not in (-1, 5))
