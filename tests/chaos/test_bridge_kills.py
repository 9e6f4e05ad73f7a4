"""Chaos: the bridge itself is killed with SIGKILL in the middle of sends, and a
PhyCloud that accepts connections but never answers."""

from __future__ import annotations

import random
import signal
import socket
import sqlite3
import threading
from pathlib import Path

import pytest

from phytrace_edge._version import __version__
from tests.bridge import bridge_settings
from tests.chaos.test_stub_outages import drain_rest
from tests.processes import BridgeProcess, wait_for

KILLS = 5
BATCH = 20


def queue_counter(path: Path, name: str) -> int:
    if not path.exists():
        return 0
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=5)
    try:
        row = db.execute("SELECT value FROM counters WHERE name = ?", (name,)).fetchone()
    except sqlite3.OperationalError:  # not created yet
        return 0
    finally:
        db.close()
    return int(row[0]) if row else 0


def bridge_env(tmp_path: Path, endpoint: str, **extra: str) -> dict[str, str]:
    return {
        "PHYCLOUD_ENDPOINT": endpoint,
        "QUEUE_PATH": str(tmp_path / "queue.db"),
        "BRIDGE_INPUT": "sim",
        "SAMPLE_RATE_HZ": "50",
        "BATCH_SIZE": str(BATCH),
        "FLUSH_INTERVAL_S": "0.2",
        "RETRY_MIN_S": "0.05",
        "RETRY_MAX_S": "0.5",
        **extra,
    }


def test_bridge_killed_during_sends_loses_nothing(tmp_path: Path, stub_factory) -> None:
    stub = stub_factory("--latency", "0.05")  # keep requests in flight when the kill lands
    rng = random.Random(7)
    queue = tmp_path / "queue.db"
    env = bridge_env(tmp_path, stub.endpoint)
    for kill in range(KILLS):
        bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
        try:
            target = stub.stats()["received"] + rng.randint(0, 60)
            wait_for(lambda t=target: stub.stats()["received"] > t, 60, f"sends before {kill + 1}")
            bridge.signal(signal.SIGKILL)
            bridge.wait(timeout=10)
        finally:
            bridge.stop()
    log = tmp_path / "bridge.log"
    bridge = BridgeProcess(log, **env).start()
    # its start-up line is logged once the signal handlers are in place
    wait_for(
        lambda: log.read_text().count(f"phytrace-edge {__version__}:") == KILLS + 1,
        30,
        "the last bridge to start",
    )
    target = stub.stats()["received"]
    wait_for(lambda: stub.stats()["received"] > target, 30, "the last bridge to send")
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=30) == 0

    settings = bridge_settings(tmp_path, stub.endpoint)
    drain_rest(settings)
    queued = queue_counter(queue, "queued_total")
    stats = stub.stats()
    print(
        f"\n{queued} events queued over {KILLS + 1} runs, {stats['unique']} unique at the stub, "
        f"{stats['duplicates']} duplicates"
    )
    assert stats["unique"] == queued, "an event that reached the queue never reached PhyCloud"
    assert stats["duplicates"] <= KILLS * BATCH, "more than one batch resent per kill"
    assert queue_counter(queue, "depth") == 0


class BlackHole:
    """Accepts connections and never answers."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.port = self.sock.getsockname()[1]
        self.held: list[socket.socket] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        self.sock.settimeout(0.2)
        while not self._stop.is_set():
            try:
                connection, _ = self.sock.accept()
            except TimeoutError:
                continue
            self.held.append(connection)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for connection in self.held:
            connection.close()
        self.sock.close()


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


@pytest.mark.slow
def test_an_endpoint_that_never_answers(tmp_path: Path) -> None:
    hole = BlackHole()
    queue = tmp_path / "queue.db"
    log = tmp_path / "bridge.log"
    bridge = BridgeProcess(
        log,
        **bridge_env(
            tmp_path,
            f"http://127.0.0.1:{hole.port}/api/v1",
            HTTP_TIMEOUT_S="0.5",
            SAMPLE_RATE_HZ="100",
        ),
    ).start()
    try:
        wait_for(lambda: queue_counter(queue, "depth") > 200, 60, "a backlog to build")
        first_rss, first_depth = rss_kib(bridge.process.pid), queue_counter(queue, "depth")
        wait_for(
            lambda: queue_counter(queue, "depth") > first_depth + 500, 60, "ingest to keep going"
        )
        growth_mib = (rss_kib(bridge.process.pid) - first_rss) / 1024
        assert growth_mib < 10, f"RSS grew {growth_mib:.1f} MiB while the endpoint hung"
        assert len(hole.held) >= 2, "the sender should have timed out and reconnected"
    finally:
        bridge.signal(signal.SIGTERM)
        code = bridge.wait(timeout=30)
        hole.close()
    assert code == 0
    assert "timeout" in log.read_text()
    assert queue_counter(queue, "acked_total") == 0
