"""``bridge.health`` events tell PhyCloud about an outage after it: the stub goes down,
the bridge turns unhealthy and says so in an event that waits in the queue; when the
stub is back, that event arrives, followed by the recovery."""

from __future__ import annotations

from tests.processes import wait_for


def health_events(events: list[dict]) -> list[dict]:
    return [e for e in events if e["event_type"] == "bridge.health"]


def test_an_outage_reaches_phycloud_as_health_events_after_it(stub, bridge_in_process) -> None:
    bridge = bridge_in_process(
        stub.endpoint, SAMPLE_RATE_HZ="5", HEALTH_EVENT_INTERVAL_S="30", HEALTH_NO_PROGRESS_S="1"
    )
    built = bridge.built
    try:
        wait_for(lambda: health_events(stub.events()), 30, "the start health event at PhyCloud")
        stub.kill()
        wait_for(
            lambda: any(not e["healthy"] for e in health_events(built)),
            60,
            "the bridge to notice the outage in a health event",
        )
        stub.start()
        wait_for(
            lambda: [e["healthy"] for e in health_events(stub.events())][-2:] == [False, True],
            60,
            "the outage's health event and the recovery's at PhyCloud",
        )
    finally:
        bridge.stop()

    received = health_events(stub.events())
    start, down, up, stop = received[0], received[-3], received[-2], received[-1]
    assert (start["trigger"], start["healthy"]) == ("start", True)
    assert [e["trigger"] for e in (down, up, stop)] == ["change", "change", "stop"]
    assert [e["healthy"] for e in (down, up)] == [False, True]
    assert any("waiting and nothing sent" in problem for problem in down["problems"])
    assert down["last_error_class"] == "ConnectError"
    assert down["queue"]["depth"] > 0
    assert down["captured_at"] < up["captured_at"]
    assert "/odom" in down["topics"] and down["topics"]["/odom"]["received"] > 0
