"""Strings that are not UTF-8 on the ``dds`` input (issue 31): cyclonedds decodes strictly,
and a ``take`` that meets such a sample raises and loses every sample it took. The input
takes one sample at a time, so the bad one costs only itself: it is counted as its
topic's reject ``undecodable``, and every other message still arrives.

Against real Cyclone DDS: ``phytrace-edge run --input dds`` in a process of its own, a
publisher process (``dds_text_publisher.py``), both on a private domain confined to
loopback, and the stub. The take loop itself: tests/unit/test_dds_take.py.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from tests.processes import BridgeProcess, python_env, status_json, wait_for
from tests.ros.rig import private_domain, stop_by_pid

pytest.importorskip("cyclonedds", reason="the DDS input needs cyclonedds (pip install .[dds])")

PUBLISHER = str(Path(__file__).with_name("dds_text_publisher.py"))


def transitions(events: list[dict[str, Any]]) -> list[tuple[str | None, str]]:
    """The delivery state changes the stub holds, in order: (from, to)."""
    found = [t for e in events for t in e.get("operational", {}).get("transitions", [])]
    return [(t.get("from"), t["to"]) for t in sorted(found, key=lambda t: t["at"])]


def diagnostics_seen(events: list[dict[str, Any]]) -> Counter[str]:
    """How often each non-OK diagnostic status was seen, over every event."""
    seen: Counter[str] = Counter()
    for event in events:
        for error in event.get("operational", {}).get("errors", []):
            seen[error["name"]] += error.get("occurrences", 0)
    return seen


def test_a_string_that_is_not_utf8_costs_only_its_own_sample(tmp_path: Path, stub) -> None:
    """A burst on /delivery/status with one status that is not UTF-8 among good ones and
    /diagnostics messages, and an /odom (a state topic, taken at the tick) whose frame
    is not UTF-8: every good message arrives, each bad one is counted ``undecodable``
    once and logged once, and the bridge goes on."""
    ros = {"ROS_DOMAIN_ID": str(private_domain()), "ROS_LOCALHOST_ONLY": "1"}
    queue = tmp_path / "queue.db"
    log = tmp_path / "bridge.log"
    settings: dict[str, Any] = {
        "BRIDGE_INPUT": "dds",
        "PHYCLOUD_ENDPOINT": stub.endpoint,
        "PHYCLOUD_API_KEY": "phk_test_secret_key",
        "QUEUE_PATH": str(queue),
        "SAMPLE_RATE_HZ": "10",
        "FLUSH_INTERVAL_S": "0.2",
        "HEALTH_EVENT_INTERVAL_S": "0",
        "INCIDENT_RECORDING": "false",  # /odom taken at the tick, not an incident's window
        **ros,
    }
    bridge = BridgeProcess(log, **settings).start()
    publisher = subprocess.Popen(
        [sys.executable, PUBLISHER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=python_env(**ros),
    )
    assert publisher.stdin is not None and publisher.stdout is not None
    stdin, stdout = publisher.stdin, publisher.stdout

    def alive() -> None:
        code = bridge.process.poll() if bridge.process else None
        assert code is None, f"the bridge exited ({code}):\n{log.read_text()}"

    def command(what: str) -> None:
        stdin.write(what + "\n")
        stdin.flush()
        assert stdout.readline().strip() == "sent"

    def heard(predicate: Any, what: str) -> Any:
        def found() -> Any:
            alive()
            return predicate(stub.events())

        return wait_for(found, 60, what, every=0.2)

    def rejected() -> dict[str, dict[str, int]]:
        topics = status_json(QUEUE_PATH=str(queue))[1].get("topics", {})
        return {t: topics.get(t, {}).get("rejected") for t in ("/delivery/status", "/odom")}

    try:
        assert stdout.readline().strip() == "ready"
        # warm-up: the bridge has s0 and the odometry, so its readers match the writers
        heard(
            lambda events: (
                transitions(events) == [(None, "s0")] and any("location" in e for e in events)
            ),
            "the warm-up's status and odometry",
        )
        command("burst")
        good = [f"s{i}" for i in range(10) if i != 6]
        expected = list(zip([None, *good[:-1]], good, strict=True))  # s5 -> s7
        heard(lambda events: transitions(events) == expected, f"the statuses {good}")
        undecodable = {"undecodable": 1}

        def counted() -> bool:  # status is the heartbeat's: seconds behind
            alive()
            return rejected() == {"/delivery/status": undecodable, "/odom": undecodable}

        wait_for(counted, 30, "status to count the two undecodable samples", every=0.5)
        command("last")  # and the bridge still hears, and still ticks
        heard(lambda events: transitions(events)[-1:] == [("s9", "s10")], "the last status")
        bridge.signal(signal.SIGTERM)
        assert bridge.wait(timeout=60) == 0
    finally:
        stop_by_pid(publisher, stdin.close)
        bridge.stop()
    events = stub.events()
    assert diagnostics_seen(events) == {"d1": 1, "d2": 1, "d3": 1}
    assert len(transitions(events)) == 10  # s0 .. s10 but s6, each once
    _, doc = status_json(QUEUE_PATH=str(queue))
    topics = doc["topics"]
    assert topics["/delivery/status"]["rejected"] == {"undecodable": 1}
    assert topics["/odom"]["rejected"] == {"undecodable": 1}
    assert topics["/diagnostics"]["rejected"] == {}
    text = log.read_text()
    warnings = [line for line in text.splitlines() if "undecodable" in line]
    assert len(warnings) == 2, text[-3000:]  # one for each topic: logged when it happened
    for topic in ("/delivery/status", "/odom"):
        [line] = [w for w in warnings if f"{topic}: message rejected (undecodable, 1 so far)" in w]
        assert "WARNING" in line
        assert "UnicodeDecodeError: 'utf-8' codec can't decode byte 0xff" in line
    assert "Traceback" not in text and "Exception ignored" not in text
