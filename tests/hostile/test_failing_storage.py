"""Failing storage under a running bridge, with real faults on a real process: strace
makes the queue's writes fail (EIO) or its fsyncs slow, a real ext4 volume goes
read-only through the kernel's own error path, and people delete or move the queue
while it runs. After each: every event built is delivered, queued, or counted by
reason (the accounting in ``status --json`` adds up), and ``status`` names the cause.

Needs root (strace attaching to another process, mounting a loop volume); CI runs as
root and .ci/run installs strace.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.processes import BridgeProcess, StubProcess, status_json, wait_for

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(os.geteuid() != 0, reason="strace and mounts need root (CI runs as root)"),
    pytest.mark.skipif(shutil.which("strace") is None, reason="strace is not installed"),
]

GRACE_S = 3.0
TIMEOUT_STOP_S = 20.0  # systemd/phytrace-edge.service's TimeoutStopSec


class Strace:
    """strace attached to every thread of a running process, injecting a fault into
    the syscalls on the queue's files; stopped (detached) by its pid."""

    def __init__(self, pid: int, syscalls: str, inject: list[str], paths: list[Path]) -> None:
        command = [
            "strace",
            "-f",
            "-q",
            "-p",
            str(pid),
            "-e",
            f"trace={syscalls}",
            "-o",
            "/dev/null",
        ]
        for fault in inject:
            command += ["-e", f"inject={fault}"]
        for path in paths:
            command += ["-P", str(path)]
        self.process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()  # strace detaches and the process goes on
            self.process.wait(timeout=20)


@pytest.fixture
def stub(tmp_path: Path) -> Iterator[StubProcess]:
    stub = StubProcess(tmp_path / "stub.db")
    yield stub
    stub.stop()


def bridge_env(queue: Path, stub: StubProcess, **extra: str) -> dict[str, str]:
    return {
        "PHYCLOUD_ENDPOINT": stub.endpoint,
        "QUEUE_PATH": str(queue),
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "50",
        "RETRY_MIN_S": "0.2",
        "RETRY_MAX_S": "1",
        "FLUSH_INTERVAL_S": "0.2",
        "SHUTDOWN_GRACE_S": str(GRACE_S),
        **extra,
    }


@pytest.fixture
def bridges() -> Iterator[list[BridgeProcess]]:
    started: list[BridgeProcess] = []
    yield started
    for bridge in started:
        bridge.stop()


def start(bridges: list[BridgeProcess], log: Path, env: dict[str, str]) -> BridgeProcess:
    bridge = BridgeProcess(log, **env).start()
    bridges.append(bridge)
    assert bridge.process is not None
    pid = bridge.process.pid
    wait_for(lambda: status(env).get("service", {}).get("pid") == pid, 60, "the bridge to run")
    return bridge


def status(env: dict[str, str]) -> dict[str, Any]:
    return status_json(**env)[1]


def balanced(document: dict[str, Any]) -> dict[str, Any]:
    """The accounting of a status document, after asserting that it adds up."""
    a = document["accounting"]
    assert a["balanced"], a
    assert a["built"] == (
        a["delivered"]
        + a["exported"]
        + a["queued"]
        + a["dead_lettered"]
        + sum(a["dropped"].values())
        + a["in_memory"]
    ), a
    return a


def unhealthy_with(env: dict[str, str], words: str, timeout: float = 20) -> dict[str, Any]:
    """Wait until ``status`` exits 1 naming ``words`` among its problems."""

    def named() -> dict[str, Any] | None:
        code, document = status_json(**env)
        problems = " | ".join(document.get("problems", []))
        return document if code == 1 and words in problems else None

    return wait_for(named, timeout, f"status to be unhealthy naming {words!r}")


def stop(bridge: BridgeProcess, expect: int | tuple[int, ...]) -> str:
    """SIGTERM; the exit code ``expect``-ed within the unit's TimeoutStopSec; the log."""
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(TIMEOUT_STOP_S) in (expect if isinstance(expect, tuple) else (expect,))
    text = bridge.log.read_text()
    assert "Traceback" not in text, text[-3000:]
    return text


def test_a_window_of_io_errors_is_named_held_in_memory_and_written_after(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    queue = tmp_path / "q" / "queue.db"
    env = bridge_env(queue, stub.start())
    bridge = start(bridges, tmp_path / "bridge.log", env)
    assert bridge.process is not None
    fault = Strace(
        bridge.process.pid, "pwrite64", ["pwrite64:error=EIO"], [Path(f"{queue}-wal"), queue]
    )
    try:
        during = unhealthy_with(env, "queue writes have failed")
        assert "disk I/O error" in during["storage"]["last_write_error"]
        assert during["running"] and during["storage"]["backlog"] > 0
        assert wait_for(
            lambda: status(env)["storage"]["backlog"] > 200, 30, "events to wait in memory"
        )
    finally:
        fault.stop()
    wait_for(
        lambda: (d := status(env))["healthy"] and d["storage"]["backlog"] == 0,
        30,
        "the writes to work again and the backlog to be written",
    )
    log = stop(bridge, expect=0)
    assert log.count("queue writes fail (") == 1  # the first failure, then summaries
    final = status(env)
    a = balanced(final)
    assert a["dropped"] == {} and a["in_memory"] == 0  # what the stop left is queued
    assert stub.stats()["unique"] == a["delivered"] == a["built"] - a["queued"]


def test_a_stop_while_writes_fail_counts_what_could_not_be_written_and_exits_non_zero(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    queue = tmp_path / "q" / "queue.db"
    env = bridge_env(queue, stub.start())
    bridge = start(bridges, tmp_path / "bridge.log", env)
    assert bridge.process is not None
    fault = Strace(
        bridge.process.pid,
        "pwrite64,fdatasync",
        ["pwrite64:error=EIO", "fdatasync:error=EIO"],
        [Path(f"{queue}-wal"), queue],
    )
    try:
        unhealthy_with(env, "queue writes have failed")
        wait_for(lambda: status(env)["storage"]["backlog"] > 50, 30, "events to wait in memory")
        log = stop(bridge, expect=4)
    finally:
        fault.stop()
    lost = [line for line in log.splitlines() if "could not be written to the queue" in line]
    assert lost and "unwritable" in lost[-1]

    after = status(env)  # the queue could not take the last counts: the live status has them
    assert not after["running"]
    a = balanced(after)
    unwritable = a["dropped"]["unwritable"]
    assert unwritable > 50 and a["in_memory"] == 0

    # the next run writes those counts into the queue and delivers the rest
    bridge = start(bridges, tmp_path / "bridge2.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] == 0, 60, "the backlog to drain")
    assert "could not write these counts" in stop(bridge, expect=0)
    final = status(env)
    a = balanced(final)
    assert a["dropped"] == {"unwritable": unwritable}
    assert stub.stats()["unique"] == a["delivered"] == a["built"] - unwritable


def test_a_deleted_queue_file_is_copied_back_and_nothing_is_lost(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    queue = tmp_path / "q" / "queue.db"
    env = bridge_env(queue, stub)  # PhyCloud down: the backlog is only in the file
    bridge = start(bridges, tmp_path / "bridge.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] > 100, 30, "a backlog")
    queue.unlink()
    wait_for(
        lambda: "copied the open queue back" in bridge.log.read_text(), 20, "the file copied back"
    )
    assert "was deleted while the bridge had it open" in bridge.log.read_text()
    after = status(env)
    assert after["healthy"] and after["queue"]["depth"] > 100, after
    assert after["storage"]["file"] == "ok"

    stub.start()
    wait_for(lambda: status(env)["queue"]["depth"] == 0, 60, "the backlog to drain")
    stop(bridge, expect=0)
    a = balanced(status(env))
    assert a["dropped"] == {} and a["queued"] == 0
    assert stub.stats()["unique"] == a["delivered"] == a["built"]
    assert stub.stats()["duplicates"] == 0


def test_a_queue_folder_moved_away_is_named_and_picked_up_again_when_it_returns(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    folder = tmp_path / "q"
    queue = folder / "queue.db"
    env = bridge_env(queue, stub)
    bridge = start(bridges, tmp_path / "bridge.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] > 100, 30, "a backlog")
    folder.rename(tmp_path / "elsewhere")
    gone = unhealthy_with(env, "is gone")
    assert gone["storage"]["file"] == "folder_gone"
    assert str(tmp_path / "elsewhere" / "queue.db") in gone["storage"]["file_detail"]
    assert bridge.process is not None and bridge.process.poll() is None

    (tmp_path / "elsewhere").rename(folder)
    wait_for(lambda: status(env)["healthy"], 20, "the folder to be back")
    stub.start()
    wait_for(lambda: status(env)["queue"]["depth"] == 0, 60, "the backlog to drain")
    stop(bridge, expect=0)
    a = balanced(status(env))
    assert a["dropped"] == {} and stub.stats()["unique"] == a["delivered"] == a["built"]


def test_a_slow_disk_is_named_and_the_stop_stays_within_the_units_timeout(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    queue = tmp_path / "q" / "queue.db"
    env = bridge_env(queue, stub.start())
    bridge = start(bridges, tmp_path / "bridge.log", env)
    assert bridge.process is not None
    fault = Strace(
        bridge.process.pid,
        "fdatasync,fsync",
        ["fdatasync:delay_enter=3s", "fsync:delay_enter=3s"],
        [Path(f"{queue}-wal"), queue],
    )
    try:
        slow = unhealthy_with(env, "before they reach the disk", timeout=60)
        assert slow["storage"]["commit_max_s"] >= 2.5, slow["storage"]
        assert any("disk is slow" in w for w in slow["warnings"]), slow["warnings"]
        stop(bridge, expect=(0, 4))  # within TimeoutStopSec, whatever could be written
    finally:
        fault.stop()
    a = balanced(status(env))
    assert bridge.process.returncode == (4 if a["dropped"].get("unwritable") else 0)
    assert stub.stats()["unique"] == a["delivered"]


@pytest.fixture
def ext4_volume(tmp_path: Path) -> Iterator[tuple[Path, Path]]:
    """A real 64 MiB ext4 file system on a loop device, mounted errors=remount-ro:
    (mount point, image)."""
    if shutil.which("mkfs.ext4") is None:
        pytest.skip("mkfs.ext4 is not installed (e2fsprogs)")
    image, mount = tmp_path / "volume.img", tmp_path / "volume"
    mount.mkdir()
    with image.open("wb") as out:
        out.truncate(64 * 1024 * 1024)
    subprocess.run(["mkfs.ext4", "-q", "-F", str(image)], check=True, capture_output=True)
    mounted = subprocess.run(
        ["mount", "-o", "loop,errors=remount-ro", str(image), str(mount)],
        capture_output=True,
        text=True,
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a loop device here: {mounted.stderr.strip()}")
    yield mount, image
    subprocess.run(["umount", "-l", str(mount)], check=False)


def force_read_only(mount: Path) -> None:
    """Make the kernel find an error on the file system: errors=remount-ro turns it
    read-only, as a failing card does."""
    device = subprocess.run(
        ["findmnt", "-n", "-o", "SOURCE", str(mount)], capture_output=True, text=True, check=True
    ).stdout.strip()
    Path(f"/sys/fs/ext4/{Path(device).name}/trigger_fs_error").write_text("test\n")

    def refuses_writes() -> bool:
        try:
            (mount / "probe").touch()
        except OSError as exc:
            return exc.errno == errno.EROFS
        return False

    wait_for(refuses_writes, 10, "the volume to refuse writes")


def test_a_volume_gone_read_only_is_named_and_what_could_not_be_written_is_counted(
    tmp_path: Path,
    stub: StubProcess,
    bridges: list[BridgeProcess],
    ext4_volume: tuple[Path, Path],
) -> None:
    mount, image = ext4_volume
    queue = mount / "queue.db"
    env = bridge_env(queue, stub)  # PhyCloud down: what is built stays on the robot
    bridge = start(bridges, tmp_path / "bridge.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] > 50, 30, "a backlog on the volume")
    force_read_only(mount)
    during = unhealthy_with(env, "read-only file system")  # the kernel's word, in status
    assert "queue writes have failed" in " ".join(during["problems"])
    assert "read-only file system" in during["storage"]["last_write_error"]
    wait_for(lambda: status(env)["storage"]["backlog"] > 100, 30, "events to wait in memory")
    log = stop(bridge, expect=4)
    assert "unwritable" in log.splitlines()[-1]
    after = status(env)
    a = balanced(after)
    unwritable = a["dropped"]["unwritable"]
    assert unwritable > 100 and a["queued"] > 50

    # the operator repairs the volume; the next start writes the counts and sends all
    subprocess.run(["umount", str(mount)], check=True)
    subprocess.run(["e2fsck", "-f", "-y", str(image)], capture_output=True, check=False)
    subprocess.run(["mount", "-o", "loop,errors=remount-ro", str(image), str(mount)], check=True)
    stub.start()
    bridge = start(bridges, tmp_path / "bridge2.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] == 0, 60, "the backlog to drain")
    stop(bridge, expect=0)
    a = balanced(status(env))
    assert a["dropped"] == {"unwritable": unwritable}
    assert stub.stats()["unique"] == a["delivered"] == a["built"] - unwritable


def test_a_restart_refuses_to_make_a_new_queue_where_one_went_missing(
    tmp_path: Path, stub: StubProcess, bridges: list[BridgeProcess]
) -> None:
    """umount -l, or the folder moved, between two runs of one boot: the second run
    must not start an empty queue in the bare mount point and hide the old one."""
    folder = tmp_path / "q"
    queue = folder / "queue.db"
    env = bridge_env(queue, stub)  # PhyCloud down: the queue holds a backlog
    bridge = start(bridges, tmp_path / "bridge.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] > 50, 30, "a backlog")
    stop(bridge, expect=0)
    held = status(env)["queue"]["depth"]
    folder.rename(tmp_path / "unmounted")
    folder.mkdir()  # the bare mount point

    refused = BridgeProcess(tmp_path / "refused.log", **env).start()
    bridges.append(refused)
    assert refused.wait(60) == 4
    line = refused.log.read_text().strip().splitlines()[-1]
    assert f"queue {queue} is missing" in line and f"with {held} event(s) queued" in line
    assert "Traceback" not in refused.log.read_text()
    assert not queue.exists()  # nothing was made in its place

    folder.rmdir()
    (tmp_path / "unmounted").rename(folder)  # mounted again
    stub.start()
    bridge = start(bridges, tmp_path / "bridge2.log", env)
    wait_for(lambda: status(env)["queue"]["depth"] == 0, 60, "the backlog to drain")
    stop(bridge, expect=0)
    a = balanced(status(env))
    assert a["dropped"] == {} and stub.stats()["unique"] == a["delivered"] == a["built"]
