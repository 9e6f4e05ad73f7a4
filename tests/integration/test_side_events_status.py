"""A running bridge with extra topics and /rosout: `status` shows per topic what came in
and what became of it, and every side event reaches PhyCloud valid (real queue file,
real stub, the simulated robot)."""

from __future__ import annotations

from tests.processes import wait_for


def test_status_counts_extra_topics_and_logs(stub, bridge_in_process) -> None:
    bridge = bridge_in_process(
        stub.endpoint,
        SAMPLE_RATE_HZ="5",
        TOPICS_EXTRA="/motor/temperature rate_hz=0.5; /not/published",
        ROSOUT_MIN_LEVEL="info",
        ROSOUT_BURST="2",
    )
    try:
        wait_for(
            lambda: (
                any(e["event_type"] == "telemetry.topic" for e in stub.events())
                and any(e["event_type"] == "log.record" for e in stub.events())
            ),
            60,
            "extra-topic and log events at PhyCloud",
        )
        document = bridge.status()
    finally:
        bridge.stop()
    topics = document["topics"]
    temperature = topics["/motor/temperature"]
    assert temperature["received"] > 0 and temperature["events"] > 0
    assert temperature["events"] <= temperature["received"]
    assert temperature["publishers"] == 1
    assert topics["/not/published"]["publishers"] == 0  # silent, and still listed
    rosout = topics["/rosout"]
    assert rosout["records"] > 0 and rosout["records"] + rosout["suppressed"] <= rosout["received"]
    kinds = {e["event_type"] for e in stub.events()}
    assert {"telemetry.periodic", "telemetry.topic", "log.record", "bridge.health"} <= kinds
