"""What ``phytrace-edge status`` shows of a queue file, read from another process
(``queue/peek.py``'s ``read_stats``) on real queue files: the bytes its files take on
disk, when its newest event was queued, the stopped service's last heartbeat, and the
dates it gives queue times."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest

from phytrace_edge.cli import main
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Y2001, Clock, Machine, event

LIMITS = QueueLimits(max_bytes=64 * MIB)


def status_json(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, Any]]:
    """``phytrace-edge status --json`` on the queue at ``path``: its exit code and document."""
    code = main(["status", "--json", "--queue-path", str(path)])
    return code, json.loads(capsys.readouterr().out)


def on_disk(path: Path) -> int:
    """Bytes of the queue's files as the file system gives them: the database, its WAL
    and shared-memory files, and its full-disk reserve."""
    files = [Path(f"{path}{suffix}") for suffix in ("", "-wal", "-shm", "-reserve")]
    return sum(file.stat().st_size for file in files if file.exists())


def test_status_gives_the_bytes_the_queues_files_take_on_disk(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``status``'s "files" figure (and the queue_bytes metric) is what the queue takes
    from the volume; off, an operator sizing QUEUE_MAX_BYTES against the disk reads a
    wrong figure."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS) as store:
        put_events(store, [event(i, pad=500) for i in range(50)])
        assert Path(f"{path}-wal").exists()  # the service runs: every file is there
        _, document = status_json(path, capsys)
        assert document["queue"]["bytes"] == on_disk(path)
    _, document = status_json(path, capsys)  # stopped: the WAL is folded in and gone
    assert document["queue"]["bytes"] == on_disk(path)


@pytest.fixture
def clock() -> Clock:
    return Clock()


def test_the_stats_say_when_the_newest_event_was_queued(tmp_path: Path, clock: Clock) -> None:
    """The newest event's queue time is how a reader of the stats (the reboot chaos
    test, tools/bench_lanes.py) knows which events reached the disk before a power cut;
    without it every queue would look as if nothing had been queued lately."""
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=LIMITS, clock=clock) as store:
        first = clock.now
        put_events(store, [event(1)])
        clock.now += 5.0
        put_events(store, [event(2)])
        clock.now += 60.0
        put_events(store, [event(3)])
    stats = read_stats(str(path), now=clock.now)
    assert stats is not None
    assert (stats.oldest_queued_at, stats.newest_queued_at) == (first, clock.now)


def test_status_shows_the_last_heartbeat_of_a_stopped_service(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """After the service stopped (no live status file), ``status`` tells which service
    last ran on this queue from the heartbeat it left in the file; without it, status
    fails or says nothing of the service the operator is looking for."""
    path = tmp_path / "queue.db"
    last_words = {
        "pid": 4242,
        "version": "9.9.9",
        "input": "sim",
        "source_id": "robot-7",
        "endpoint_host": "phycloud.example",
        "running": False,
    }
    with QueueStore.open(path, limits=LIMITS) as store:
        store.write_service_state(last_words, running=False)
    code, document = status_json(path, capsys)
    assert code == 3  # not running
    assert document["running"] is False and document["heartbeat_age_s"] is not None
    assert document["service"] == {
        "pid": 4242,
        "version": "9.9.9",
        "input": "sim",
        "source_id": "robot-7",
        "endpoint_host": "phycloud.example",
        "started_at": None,
    }


def test_status_dates_queue_times_on_todays_wall_clock(tmp_path: Path) -> None:
    """A queue written on a robot that booted in 2001 (no real-time clock) keeps its
    queue time there; ``status`` run later turns queue times into dates with the wall
    clock minus queue time (its last success, its last error, a clock step): the moment
    it read the queue must come out as the moment it ran, not decades away."""
    path = tmp_path / "queue.db"
    machine = Machine(wall=Y2001)
    with QueueStore.open(path, limits=LIMITS, clocks=machine) as store:  # type: ignore[arg-type]
        put_events(store, [event(1)])
    before = time.time()
    stats = read_stats(str(path))  # another process, on this machine's real clocks
    after = time.time()
    assert stats is not None
    assert stats.read_at < before - 3600  # queue time is still in 2001: far from the date
    assert before <= stats.read_at + stats.clock.wall_offset <= after
