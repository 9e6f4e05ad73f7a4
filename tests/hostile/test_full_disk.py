"""A real full filesystem (a small tmpfs mounted for the test, so root only): the bridge
keeps running while PhyCloud is down and something else fills the disk under it, counts
every event it could not keep, survives a restart on the full disk, and drains by itself
once PhyCloud is back — while the disk is still full, and after space returns.

(The queue alone never fills its volume: its cap follows the volume's free space,
tests/hostile/test_volume_space.py. Here another file takes every byte left while the
bridge runs, so SQLite really reports SQLITE_FULL and the reserve is given up.)"""

from __future__ import annotations

import errno
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.hostile.volumes import tmpfs
from tests.processes import BridgeProcess, StubProcess, status_json, wait_for

VOLUME_MB = 8

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0, reason="mounting a tmpfs needs root (CI runs as root)"
)


@pytest.fixture
def volume(tmp_path: Path) -> Iterator[Path]:
    with tmpfs(tmp_path / "volume", VOLUME_MB) as path:
        yield path


def fill(volume: Path) -> Path:
    """A file that takes every byte left on the volume (written until ENOSPC: the
    bridge writes to the same volume meanwhile)."""
    filler = volume / "filler"
    chunk = b"\0" * 65536
    with filler.open("wb", buffering=0) as out:
        while True:
            try:
                out.write(chunk)
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                break
    return filler


def status(env: dict[str, str]) -> dict:
    return status_json(**env)[1]


def test_a_full_disk_is_survived_counted_and_drained_by_itself(
    volume: Path, tmp_path: Path
) -> None:
    stub = StubProcess(tmp_path / "stub.db")  # PhyCloud: down until the disk is full
    env = {
        "PHYCLOUD_ENDPOINT": stub.endpoint,
        "QUEUE_PATH": str(volume / "queue.db"),
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "100",
        "QUEUE_COMPRESSION": "none",
        "RETRY_MIN_S": "0.2",
        "RETRY_MAX_S": "1",
        "FLUSH_INTERVAL_S": "0.2",
        "BATCH_SIZE": "50",
    }
    bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
    try:
        wait_for(lambda: status(env).get("queue", {}).get("depth", 0) > 300, 60, "events")
        filler = fill(volume)  # another program takes the rest of the disk
        full = wait_for(
            lambda: (doc := status(env)).get("drops", {}).get("disk_full") and doc,
            120,
            "the disk to fill and events to be refused",
        )
        assert full["running"], full
        assert bridge.process.poll() is None

        # a restart on the full disk: the new bridge must start and keep running
        bridge.signal(signal.SIGKILL)
        bridge.wait(10)
        bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
        restarted = wait_for(
            lambda: (
                (doc := status(env)).get("service", {}).get("pid") == bridge.process.pid and doc
            ),
            60,
            "the restarted bridge's heartbeat",
        )
        assert restarted["running"] and bridge.process.poll() is None

        # PhyCloud back while the disk is still full: the running bridge drains
        stub.start()
        wait_for(lambda: stub.stats()["unique"] > 500, 120, "sending on a full disk")
        assert os.statvfs(volume).f_bavail * os.statvfs(volume).f_frsize < 1024 * 1024

        # space returns: everything left goes, by itself
        filler.unlink()
        reserve = volume / "queue.db-reserve"
        wait_for(lambda: reserve.exists(), 10, "the reserve to be made again")
        wait_for(lambda: status(env)["queue"]["depth"] < 60, 120, "the backlog to drain")
        bridge.signal(signal.SIGTERM)
        assert bridge.wait(60) == 0
        delivered = stub.stats()["unique"]
    finally:
        bridge.stop()
        stub.stop()

    final = status(env)
    drops = final["drops"]
    assert drops.get("disk_full", 0) > 0
    # every event built is accounted for: delivered, still queued, or counted as dropped
    assert final["queued_total"] == final["sent_total"] + final["queue"]["depth"] + sum(
        n for reason, n in drops.items() if reason != "writer_backlog"
    )
    assert final["queue"]["depth"] == 0
    assert delivered == final["sent_total"]
    log = (tmp_path / "bridge.log").read_text()
    assert "released the queue's" in log, "SQLite really ran out of space"
    assert "the disk has room again; the reserve is back" in log
