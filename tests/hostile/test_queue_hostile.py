"""The queue file under hostile conditions, on real files and real processes: another
process holding the write lock, a killed owner's claims, a device or a read-only place
as QUEUE_PATH, a queue from a newer version, another application's database, and two
services on one file."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import stat
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from phytrace_edge.queue.peek import read_stats
from phytrace_edge.queue.store import QueueStore
from tests.processes import BridgeProcess, python_env, run_cli, wait_for
from tests.queue_events import put_events

ROOT = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (mknod, mount); CI runs as root")


def run_bridge(tmp_path: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return run_cli("run", "--input", "sim", timeout=60, **env)


def one_line(result: subprocess.CompletedProcess[str]) -> str:
    lines = result.stderr.strip().splitlines()
    assert "Traceback" not in result.stderr and len(lines) == 1, result.stderr
    return lines[0]


HOLD_LOCK = """
import sqlite3, sys
db = sqlite3.connect(sys.argv[1], isolation_level=None)
db.execute("BEGIN IMMEDIATE")
print("locked", flush=True)
sys.stdin.readline()  # until the test has seen what it waits for
db.execute("ROLLBACK")
"""


def lock_with_events_waiting(queue: Path) -> subprocess.Popen[str]:
    """Another process holding the queue's write lock while events wait, so that the
    sender has a claim or an ack to make and meets the lock. The queue may happen to be
    empty the moment the lock is taken (the sender keeps up with the robot), and then
    stays so (the writer cannot add events under the lock): then take it again."""
    deadline = time.monotonic() + 30
    while True:
        holder = subprocess.Popen(
            [sys.executable, "-c", HOLD_LOCK, str(queue)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "locked"
        stats = read_stats(str(queue))
        if stats is not None and stats.depth > 0:
            return holder
        holder.communicate("release\n", timeout=30)
        assert time.monotonic() < deadline, "the queue stayed empty: no events to meet the lock"


def test_another_process_holding_the_write_lock_pauses_sending_not_the_bridge(
    tmp_path: Path, stub, bridge_in_process
) -> None:
    """While another process holds the write lock the sender meets it on its next claim
    (it claims every FLUSH_INTERVAL_S), counts it, and the robot's events keep being
    built; once the lock is gone sending resumes and nothing is lost. (Whether `status`
    names the problem depends on whether a send succeeded since; the verdict itself is
    tested in tests/unit/test_health.py.)"""
    # the stop waits only until the queue is empty: room for a busy machine
    bridge = bridge_in_process(stub.endpoint, SAMPLE_RATE_HZ="20", SHUTDOWN_GRACE_S="60")
    service, built = bridge.service, bridge.built
    holder = None
    try:
        wait_for(lambda: service.sender.stats.events_sent > 10, 30, "the first sends")
        holder = lock_with_events_waiting(tmp_path / "queue.db")
        # the writer, the heartbeat and the sender each wait out the busy timeout in turn
        wait_for(lambda: service.sender.stats.queue_errors > 0, 60, "the sender to meet the lock")
        during = len(built)
        wait_for(lambda: len(built) > during + 20, 30, "the robot's events built meanwhile")
        holder.communicate("release\n", timeout=30)
        sent = service.sender.stats.events_sent
        wait_for(lambda: service.sender.stats.events_sent > sent + 20, 30, "sending to resume")
        # sending works again, so status soon says healthy (a stage that waited out the
        # lock may show its wait for a heartbeat or two)
        after = wait_for(
            lambda: (doc := bridge.status())["healthy"] and doc, 30, "status to be healthy again"
        )
        assert after["queue_errors"] == service.sender.stats.queue_errors > 0
    finally:
        if holder is not None and holder.poll() is None:
            holder.kill()
    bridge.stop()
    assert service.supervisor.restarts["sender"] == 0  # paused, never crashed
    assert service.store_depth_at_stop == 0
    assert set(stub.event_ids()) == bridge.built_ids()


CLAIM_AND_WAIT = """
import sys
from phytrace_edge.queue.store import QueueStore
store = QueueStore.open(sys.argv[1])
batch = store.claim_batch(100, 10**7)
print(len(batch.events), flush=True)
sys.stdin.read()
"""


def test_a_killed_owners_claims_are_taken_back_at_once(tmp_path: Path) -> None:
    path = tmp_path / "queue.db"
    with QueueStore.open(path) as store:
        put_events(store, [{"event_id": f"e{i}"} for i in range(30)])
    owner = subprocess.Popen(
        [sys.executable, "-c", CLAIM_AND_WAIT, str(path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=python_env(),
    )
    try:
        assert owner.stdout.readline().strip() == "30"
        with QueueStore.open(path, lease_s=3600) as other:
            assert other.claim_batch(100, 10**7) is None  # a live owner's claim holds
            os.kill(owner.pid, signal.SIGKILL)
            owner.wait(10)
            batch = other.claim_batch(100, 10**7)  # no waiting for the lease (an hour)
            assert batch is not None and len(batch.events) == 30
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
    with QueueStore.open(path) as reopened:  # and a new process finds them free too
        assert reopened.stats().leased == 0


@ROOT
def test_a_character_device_as_queue_path_is_refused_and_left_alone(tmp_path: Path) -> None:
    device = tmp_path / "null"
    os.mknod(device, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a /dev/null of our own
    device.chmod(0o666)
    result = run_bridge(tmp_path, QUEUE_PATH=str(device))
    assert result.returncode == 4
    assert "not a regular file" in one_line(result)
    assert stat.S_IMODE(device.stat().st_mode) == 0o666  # never chmod'ed


@ROOT
def test_a_new_queue_in_a_read_only_place_is_one_line(
    tmp_path: Path, read_only_mount: ReadOnlyMount
) -> None:
    place = read_only_mount(tmp_path / "empty")
    result = run_bridge(tmp_path, QUEUE_PATH=str(place / "queue.db"))
    assert result.returncode == 4
    assert "(Read-only file system)" in one_line(result)


@ROOT
def test_status_reads_a_queue_on_a_read_only_volume(
    tmp_path: Path, read_only_mount: ReadOnlyMount
) -> None:
    source = tmp_path / "rw"
    source.mkdir()
    with QueueStore.open(source / "queue.db") as store:
        put_events(store, [{"event_id": f"e{i}"} for i in range(7)])
    place = read_only_mount(source)
    result = run_cli("status", "--json", timeout=60, QUEUE_PATH=str(place / "queue.db"))
    assert result.returncode == 3, result.stderr  # not running, and readable
    queue = json.loads(result.stdout)["queue"]
    assert (queue["path"], queue["depth"]) == (str(place / "queue.db"), 7)


ReadOnlyMount = Callable[[Path], Path]


@pytest.fixture
def read_only_mount(tmp_path: Path) -> Iterator[ReadOnlyMount]:
    """Makes a read-only bind mount of a folder (created if missing); every one is
    unmounted when the test ends, so none outlives it."""
    mounted: list[Path] = []

    def mount(source: Path) -> Path:
        source.mkdir(exist_ok=True)
        target = tmp_path / f"read-only-{len(mounted)}"
        target.mkdir()
        for command in (
            ["mount", "--bind", str(source), str(target)],
            ["mount", "-o", "remount,ro,bind", str(target)],
        ):
            done = subprocess.run(command, capture_output=True, text=True, timeout=30)
            if command[1] == "--bind" and done.returncode == 0:
                mounted.append(target)
            if done.returncode:
                pytest.skip(f"cannot make a read-only mount here: {done.stderr.strip()}")
        return target

    yield mount
    for target in mounted:
        subprocess.run(["umount", str(target)], check=True, timeout=30)


def test_a_queue_from_a_newer_version_is_refused_not_used(tmp_path: Path) -> None:
    path = tmp_path / "queue.db"
    with QueueStore.open(path) as store:
        store.put({"event_id": "keep-me"})
    db = sqlite3.connect(path)
    db.execute("PRAGMA user_version = 99")
    db.close()  # (a `with` block only commits: the checkpoint comes at close)
    before = path.read_bytes()
    result = run_bridge(tmp_path, QUEUE_PATH=str(path))
    assert result.returncode == 4
    line = one_line(result)
    assert "schema version 99" in line and "upgrade phytrace-edge" in line
    assert path.read_bytes() == before  # not migrated, not moved, not touched


def test_another_applications_database_is_moved_aside(tmp_path: Path) -> None:
    path = tmp_path / "queue.db"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE photos(id INTEGER PRIMARY KEY, caption TEXT)")
        db.execute("INSERT INTO photos(caption) VALUES ('holiday')")
    with QueueStore.open(path) as store:
        assert store.stats().quarantined is not None
        moved = Path(store.stats().quarantined)
    with sqlite3.connect(moved) as db:  # the other application's data, intact
        assert db.execute("SELECT caption FROM photos").fetchone() == ("holiday",)
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
    assert "events" not in tables  # no queue tables were added to it


def test_a_second_run_on_the_same_queue_is_refused_with_the_first_ones_pid(
    tmp_path: Path,
) -> None:
    env = {"QUEUE_PATH": str(tmp_path / "queue.db"), "BRIDGE_INPUT": "sim"}
    first = BridgeProcess(tmp_path / "first.log", **env).start()
    try:
        wait_for(lambda: Path(f"{tmp_path / 'queue.db'}.lock").exists(), 30, "the first run")
        wait_for(lambda: "input sim" in (tmp_path / "first.log").read_text(), 30, "its start")
        second = run_bridge(tmp_path, **env)
        assert second.returncode == 4
        assert f"in use by another phytrace-edge run (pid {first.process.pid})" in one_line(second)
        drain = run_cli("drain", "--timeout", "1", timeout=60, **env)
        assert "in use" not in drain.stderr  # drain beside the service stays allowed
        assert first.process.poll() is None
    finally:
        first.stop()
