"""A running bridge with extra topics and /rosout: `status` shows per topic what came in
and what became of it, and every side event reaches PhyCloud valid (real queue file,
real stub, the simulated robot)."""

from __future__ import annotations

from pathlib import Path

from phytrace_edge.queue.inspect import read_stats
from phytrace_edge.runtime import wiring
from phytrace_edge.runtime.health import report
from tests.chaos.test_stub_outages import bridge_settings
from tests.processes import wait_for


def test_status_counts_extra_topics_and_logs(tmp_path: Path, stub) -> None:
    settings = bridge_settings(
        tmp_path,
        stub.endpoint,
        SAMPLE_RATE_HZ="5",
        TOPICS_EXTRA="/motor/temperature rate_hz=0.5; /not/published",
        ROSOUT_MIN_LEVEL="info",
        ROSOUT_BURST="2",
    )
    service = wiring.build_service(settings, {})
    service.start()
    try:
        wait_for(
            lambda: (
                any(e["event_type"] == "telemetry.topic" for e in stub.events())
                and any(e["event_type"] == "log.record" for e in stub.events())
            ),
            60,
            "extra-topic and log events at PhyCloud",
        )
        service.heartbeat(running=True)
        document = report(
            read_stats(wiring.queue_path(settings), service.store.now()),
            wiring.health_thresholds(settings),
            service.store.now(),
        )
    finally:
        service.shutdown(settings.shutdown_grace_s)
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
