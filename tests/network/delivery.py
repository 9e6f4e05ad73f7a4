"""A real bridge process (``run --input sim``) delivering to a real stub process in a
company network's set-up, and the accounting of every event it built."""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

from tests.processes import BridgeProcess, StubProcess, status_json, wait_for

SIM = {
    "BRIDGE_INPUT": "sim",
    "SAMPLE_RATE_HZ": "20",
    "FLUSH_INTERVAL_S": "0.2",
    "BATCH_SIZE": "10",
    "RETRY_MIN_S": "0.1",
    "RETRY_MAX_S": "1",
}


def start_bridge(
    tmp_path: Path, endpoint: str, command: list[str] | None = None, **env: str
) -> tuple[BridgeProcess, dict[str, str]]:
    """The bridge, started (by ``command``, a wrapper, when given); and the settings
    ``status`` needs to read its queue."""
    queue = str(tmp_path / "queue.db")
    settings = {**SIM, "PHYCLOUD_ENDPOINT": endpoint, "QUEUE_PATH": queue, **env}
    bridge = BridgeProcess(tmp_path / "bridge.log", command=command, **settings)
    return bridge.start(), settings


def stop_and_account(bridge: BridgeProcess, settings: dict[str, str]) -> dict[str, Any]:
    """SIGTERM, a clean exit, and the run's accounting, checked to add up."""
    bridge.signal(signal.SIGTERM)
    assert bridge.wait(timeout=60) == 0, "the bridge did not stop cleanly"
    _, document = status_json(**settings)
    accounting = document["accounting"]
    assert accounting["balanced"], accounting
    assert accounting["built"] == (
        accounting["delivered"]
        + accounting["exported"]
        + accounting["queued"]
        + accounting["dead_lettered"]
        + sum(accounting["dropped"].values())
        + accounting["in_memory"]
    ), accounting
    return accounting


def delivered_everything(
    bridge: BridgeProcess, settings: dict[str, str], stub: StubProcess, at_least: int = 30
) -> dict[str, Any]:
    """Wait for ``at_least`` events at the stub, stop the bridge, and check that every
    event it built reached the stub exactly once: none queued, none lost."""
    wait_for(lambda: stub.stats()["unique"] >= at_least, 60, f"{at_least} events at PhyCloud")
    accounting = stop_and_account(bridge, settings)
    received = stub.stats()
    print(f"accounting {accounting}; PhyCloud stored {received['unique']}")  # for -s runs
    assert accounting["dropped"] == {}, accounting
    assert accounting["dead_lettered"] == 0, accounting
    assert received["unique"] == received["received"] == accounting["delivered"], received
    # the stop flushes: what was built is at PhyCloud, not left behind
    assert accounting["queued"] == 0 and accounting["in_memory"] == 0, accounting
    return accounting


def running_status(settings: dict[str, str]) -> tuple[int, dict[str, Any]] | None:
    """``status --json`` once the bridge runs and says how it reaches PhyCloud."""
    code, document = status_json(**settings)
    return (code, document) if document.get("running") and document.get("link") else None


def unhealthy_naming(settings: dict[str, str], words: str) -> tuple[int, dict[str, Any]] | None:
    """``status --json`` once it is unhealthy with ``words`` among its problems."""
    code, document = status_json(**settings)
    problems = " | ".join(document.get("problems", []))
    return (code, document) if code == 1 and words in problems else None
