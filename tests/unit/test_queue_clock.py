"""Queue time on real SQLite files, with the machine's clocks stood in for: the wall
clock steps (forward by years, back by a day) while events wait and across reboots,
and no event is expired, no lease runs out, and no count moves because of it.
(tests/chaos/test_clock_steps.py does the same with real processes under libfaketime.)"""

from __future__ import annotations

import ctypes
from datetime import datetime
from pathlib import Path

import orjson
import pytest

from phytrace_edge.handcarry.reader import open_export
from phytrace_edge.handcarry.transfer import export_backlog
from phytrace_edge.host_clock import synchronized
from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.queue.timekeeping import repair
from phytrace_edge.queue.timekeeping.clock import Instant, LastSeen, Step, boot_base
from phytrace_edge.queue.timekeeping.repair import stamped_before
from phytrace_edge.runtime.health import Thresholds, report
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import NOW, Y2001, Machine, event, put_stamped, seqs, stamped

DAY = 86_400.0
TTL = QueueLimits(max_bytes=64 * MIB, ttl_s=7 * DAY)


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
    put_events(store, [event(i) for i in range(5)])
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
    put_events(store, [event(i) for i in range(3)])
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
    put_events(store, [event(i) for i in range(4)])
    machine.run(120.0)
    store.maintain()
    store.close()
    machine.reboot(wall=NOW, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    store.maintain()
    stats = store.stats()
    assert stats.drops == {}
    assert stats.oldest_queued_at is not None
    assert store.now() - stats.oldest_queued_at == pytest.approx(128.0)
    assert seqs(store.claim_batch(10, MIB)) == [0, 1, 2, 3]
    store.close()


def rebooted_with_two_events(
    tmp_path: Path, wall: float, synchronized: bool
) -> tuple[Machine, QueueStore]:
    """Two events queued on a synchronized clock; then a reboot with ``wall``."""
    machine = Machine(wall=NOW, synchronized=True)
    store = open_store(tmp_path / "q.db", machine)
    put_events(store, [event(i) for i in range(2)])
    store.maintain()
    store.close()
    machine.reboot(wall=wall, synchronized=synchronized)
    return machine, open_store(tmp_path / "q.db", machine)


def test_time_off_counts_when_the_clock_was_true_before_and_after(tmp_path: Path) -> None:
    _, store = rebooted_with_two_events(tmp_path, wall=NOW + 8 * DAY, synchronized=True)
    assert store.expire() == 2  # really 8 days old: the TTL is 7
    store.close()


def test_the_reverse_a_right_clock_then_a_wrong_one(tmp_path: Path) -> None:
    machine, store = rebooted_with_two_events(tmp_path, wall=Y2001, synchronized=False)
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
    assert synchronized() is (None if state == -1 else state != 5)


def claimed(store: QueueStore) -> dict[int, dict]:
    batch = store.claim_batch(1000, 64 * MIB)
    assert batch is not None
    events = {orjson.loads(e.json)["seq"]: orjson.loads(e.json) for e in batch.events}
    store.ack(batch)
    return events


@pytest.mark.parametrize("step_s", [NOW - Y2001, -DAY, 3.5])
def test_stamps_queued_before_a_step_are_repaired(tmp_path: Path, step_s: float) -> None:
    machine = Machine(wall=Y2001 if step_s > DAY else NOW)
    store = open_store(tmp_path / "q.db", machine)
    store.record_clocks()  # the heartbeat's look before the step
    put_stamped(store, machine, range(5))
    sending = store.claim_batch(1, MIB)  # event 0 is being sent when the step comes
    machine.run(0.5)
    machine.wall += step_s
    machine.synchronized = True
    put_stamped(store, machine, range(5, 7))  # stamped after the step, before it is seen
    machine.run(1.0)
    assert store.record_clocks() == pytest.approx(step_s)
    store.release(sending)

    assert store.stepped_since(sending.claimed_at)  # its sender gives it back
    events = claimed(store)
    assert sorted(events) == list(range(7))
    for n in range(5):  # the one being sent at the step too
        assert events[n]["wall_clock"]["corrected_by_s"] == pytest.approx(step_s, abs=1e-3)
        assert events[n]["wall_clock"]["synchronized"] is False
    stamped_at = {n: datetime.fromisoformat(e["captured_at"][:-1]) for n, e in events.items()}
    # repaired stamps line up with the ones taken after the step: 0.2 s apart
    assert (stamped_at[5] - stamped_at[4]).total_seconds() == pytest.approx(0.7, abs=0.01)
    for n in (5, 6):
        assert "wall_clock" not in events[n]  # stamped on the synchronized clock
    store.close()


def test_frames_are_repaired_event_by_event(tmp_path: Path) -> None:
    machine = Machine(wall=Y2001)
    store = QueueStore.open(
        tmp_path / "q.db",
        limits=TTL,
        clocks=machine,
        frame_events=4,  # type: ignore[arg-type]
    )
    store.record_clocks()
    put_stamped(store, machine, range(8))
    machine.run(SEAL_AFTER_S + 1)
    put_stamped(store, machine, range(8, 9))  # the put that seals what waited
    rows = store._db.read("SELECT count(*) FROM events")[0][0]
    assert rows < 9  # frames were formed
    machine.wall, machine.synchronized = NOW, True
    machine.run(1.0)
    store.record_clocks()
    events = claimed(store)
    assert all(e["wall_clock"].get("corrected_by_s") for e in events.values())
    assert all(e["captured_at"].startswith("2026-") for e in events.values())
    stats = store.stats()
    assert stats.depth == 0 and stats.drops == {}
    store.close()


def test_stamps_of_an_earlier_boot_are_not_repaired(tmp_path: Path) -> None:
    """They were taken on the previous boot's clock, which this step says nothing about."""
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    put_stamped(store, machine, range(3))
    store.maintain()
    store.close()
    machine.reboot(wall=Y2001 + 5000.0, synchronized=False)
    store = open_store(tmp_path / "q.db", machine)
    machine.run(5.0)
    machine.wall, machine.synchronized = NOW, True
    assert store.record_clocks() > 0
    events = claimed(store)
    assert all(e["wall_clock"] == {"synchronized": False} for e in events.values())
    store.close()


@pytest.mark.parametrize(
    ("captured_s", "expected"),
    [
        (1000.0 + 100.0, True),  # queue time 100 on the old clock (offset 1000)
        (5000.0 + 101.0, False),  # queue time 101 on the new clock (offset 5000)
        (3000.0, False),  # neither clock explains it
    ],
)
def test_which_clock_stamped_an_event(captured_s: float, expected: bool) -> None:
    step = Step(at=102.0, looked_at=100.5, offset_before=1000.0, offset_after=5000.0)
    assert stamped_before(captured_s, (99.0, 101.5), step) is expected


def test_an_event_both_clocks_explain_keeps_its_mark() -> None:
    """A step of 3 s: a stamp within the last seconds fits either clock, so it is left
    uncorrected (and still says the clock was not synchronized)."""
    step = Step(at=102.0, looked_at=100.5, offset_before=1000.0, offset_after=1003.0)
    assert stamped_before(1102.5, (101.0, 101.0), step) is False
    assert stamped_before(1090.0, (90.0, 90.0), step) is True  # long before: only the old


def test_stamps_after_the_step_on_a_still_unsynchronized_clock_are_left(tmp_path: Path) -> None:
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    store.record_clocks()
    put_stamped(store, machine, range(3))
    machine.wall = NOW  # set by hand (or GPS without discipline): still not synchronized
    put_stamped(store, machine, range(3, 5))
    machine.run(1.0)
    store.record_clocks()
    events = claimed(store)
    assert [("corrected_by_s" in events[n]["wall_clock"]) for n in range(5)] == [
        True,
        True,
        True,
        False,
        False,
    ]
    assert all(e["captured_at"].startswith("2026-") for e in events.values())
    store.close()


def test_an_export_under_way_at_a_step_writes_the_repaired_stamps(tmp_path: Path) -> None:
    machine = Machine(wall=Y2001)
    store = open_store(tmp_path / "q.db", machine)
    store.record_clocks()
    put_stamped(store, machine, range(700))  # two batches of an export

    def step_after_the_first_batch(events: int) -> None:
        if machine.wall < NOW:
            machine.wall += NOW - Y2001  # NTP, while the file is being written
            machine.run(1.0)

    path = tmp_path / "robot.phx"
    manifest = export_backlog(store, path, "robot-1", 64 * MIB, step_after_the_first_batch)
    assert manifest is not None
    written = list(open_export(path).events())
    assert sorted(e["seq"] for e in written) == list(range(700))
    assert all(e["captured_at"].startswith("2026-") for e in written)
    assert all("corrected_by_s" in e["wall_clock"] for e in written)
    assert store.stats().depth == 0
    store.close()


@pytest.fixture
def repair_by_the_chunk(monkeypatch: pytest.MonkeyPatch) -> None:
    """A repair of two rows per look, as a day's backlog goes on a slow machine."""
    monkeypatch.setattr(repair, "CHUNK_ROWS", 2)
    monkeypatch.setattr(repair, "REPAIR_BUDGET_S", 0.0)


def corrections(events: dict[int, dict]) -> dict[int, float]:
    return {n: e["wall_clock"].get("corrected_by_s", 0.0) for n, e in events.items()}


def ten_queued_in_2001(path: Path) -> tuple[Machine, QueueStore]:
    """A store with ten events stamped in 2001 on an unsynchronized clock."""
    machine = Machine(wall=Y2001)
    store = open_store(path, machine)
    store.record_clocks()
    put_stamped(store, machine, range(10))
    return machine, store


def ntp_steps(machine: Machine, seconds: float = NOW - Y2001) -> None:
    machine.wall += seconds
    machine.run(1.0)


def sent_all(store: QueueStore) -> tuple[dict[int, dict], int]:
    """Every event as the backfill sends it, by seq; and the number of batches."""
    sent: dict[int, dict] = {}
    batches = 0
    while (batch := store.claim_batch(3, MIB, important_first=False)) is not None:
        sent |= {orjson.loads(e.json)["seq"]: orjson.loads(e.json) for e in batch.events}
        store.ack(batch)
        batches += 1
    return sent, batches


@pytest.mark.usefixtures("repair_by_the_chunk")
def test_a_long_repair_goes_by_the_chunk_and_nothing_is_sent_unrepaired(tmp_path: Path) -> None:
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    sending = store.claim_batch(1, MIB)  # event 0 is on its way at the step
    ntp_steps(machine)
    store.record_clocks()  # the step seen: the held row at once, then one chunk
    store.release(sending)
    sent, batches = sent_all(store)
    assert sorted(sent) == list(range(10))
    assert list(corrections(sent).values()) == [pytest.approx(NOW - Y2001)] * 10  # each once
    assert batches > 1
    store.close()


@pytest.mark.usefixtures("repair_by_the_chunk")
def test_a_repair_cut_short_by_a_crash_goes_on_at_the_next_open(tmp_path: Path) -> None:
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    ntp_steps(machine)
    store.record_clocks()  # two rows of ten repaired
    store.close()  # as good as a crash: the repair is in meta, its lease dies with us
    store = open_store(tmp_path / "q.db", machine)
    sent, _ = sent_all(store)
    assert sorted(sent) == list(range(10))
    assert list(corrections(sent).values()) == [pytest.approx(NOW - Y2001)] * 10
    store.close()


@pytest.mark.usefixtures("repair_by_the_chunk")
def test_a_second_step_during_a_repair_applies_both(tmp_path: Path) -> None:
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    ntp_steps(machine)
    store.record_clocks()
    ntp_steps(machine, -5.0)  # chrony's second step
    assert store.record_clocks() == pytest.approx(-5.0)
    events = claimed(store)
    assert sorted(events) == list(range(10))
    assert list(corrections(events).values()) == [pytest.approx(NOW - Y2001 - 5.0)] * 10
    store.close()


# An event in flight at a step (issue 31): built, stamped on the old clock, and still in
# the writer's memory when the step is seen and the queue's rows are taken for repair.


def moved_by(seconds: float) -> object:
    return pytest.approx(seconds, abs=1e-3)


def test_an_event_in_flight_when_the_repair_ran_is_repaired_as_it_is_queued(
    tmp_path: Path,
) -> None:
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    in_flight = [stamped(n, machine) for n in (10, 11)]  # handed to the writer
    machine.run(0.2)
    ntp_steps(machine)
    assert store.record_clocks() == moved_by(NOW - Y2001)  # the queue's rows repaired
    machine.run(5.0)  # the writer was slow (a disk stall)
    put_events(store, in_flight)
    put_stamped(store, machine, range(12, 14))  # stamped after the step, still unsynchronized
    events = claimed(store)
    assert corrections(events) == {
        **{n: moved_by(NOW - Y2001) for n in range(12)},
        12: 0.0,
        13: 0.0,
    }
    assert all(e["captured_at"].startswith("2026-") for e in events.values())
    store.close()


def test_an_event_queued_long_after_its_stamp_and_before_the_step_is_repaired(
    tmp_path: Path,
) -> None:
    """The rule does not assume that an event is queued within a second or two."""
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    late = stamped(10, machine)
    machine.run(30.0)  # half a minute in the writer's memory
    store.put(late)
    ntp_steps(machine)
    store.record_clocks()
    assert corrections(claimed(store)) == {n: moved_by(NOW - Y2001) for n in range(11)}
    store.close()


def test_a_put_that_read_its_time_before_the_step_was_recorded_is_repaired(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The put reads its queue time; the heartbeat's look records the step and takes
    the rows in the queue for repair; then the put commits. Its row is queued before
    the step's time, but was not in the queue when the repair took its rows."""
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    in_flight = stamped(10, machine)
    ntp_steps(machine)
    refuses = store._full_disk.refuses  # after the put's time is read, before its commit
    looked: list[float] = []

    def the_heartbeat_looks_first(sizes: list[int]) -> bool:
        if not looked:
            looked.append(store.record_clocks())
        return refuses(sizes)

    monkeypatch.setattr(store._full_disk, "refuses", the_heartbeat_looks_first)
    store.put(in_flight)
    assert looked == [moved_by(NOW - Y2001)]
    assert corrections(claimed(store)) == {n: moved_by(NOW - Y2001) for n in range(11)}
    store.close()


def test_an_event_in_flight_over_two_steps_is_moved_by_both(tmp_path: Path) -> None:
    machine, store = ten_queued_in_2001(tmp_path / "q.db")
    first = stamped(10, machine)  # on the 2001 clock
    ntp_steps(machine)
    store.record_clocks()
    second = stamped(11, machine)  # on the stepped clock, still unsynchronized
    ntp_steps(machine, -5.0)  # chrony's second step
    assert store.record_clocks() == moved_by(-5.0)
    put_events(store, [first, second])
    assert corrections(claimed(store)) == {
        **{n: moved_by(NOW - Y2001 - 5.0) for n in range(11)},
        11: moved_by(-5.0),
    }
    store.close()


@pytest.mark.parametrize(
    ("offset_after", "stamped_at", "queued_at", "expected"),
    [
        (5000.0, 50.0, 500.0, True),  # queued 450 s after its stamp
        (5000.0, 5.0, 500.0, False),  # before this boot started (at 10)
        (997.0, 101.0, 101.05, True),  # a step back by 3 s: stamped before it
        # stamped after that step and queued at once: the old clock's reading (98.9)
        # fits as well, so it is left
        (997.0, 101.9, 101.9, False),
    ],
)
def test_how_long_an_event_waited_before_it_was_queued_does_not_matter(
    offset_after: float, stamped_at: float, queued_at: float, expected: bool
) -> None:
    step = Step(at=102.0, looked_at=100.5, offset_before=1000.0, offset_after=offset_after)
    clock = step.offset_before if stamped_at < 101.5 else step.offset_after  # stepped at 101.5
    assert stamped_before(stamped_at + clock, (10.0, queued_at), step) is expected
