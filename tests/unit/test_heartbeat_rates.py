"""The per-second rates ``status`` shows (``runtime.heartbeat.Rates``)."""

from __future__ import annotations

from phytrace_edge.runtime.heartbeat import Rates


def test_a_topic_first_heard_between_two_heartbeats_has_its_rate() -> None:
    """Three /rosout records between two heartbeats 2 s apart: 1.5 Hz (it showed 0.0
    for ever: a counter absent at the previous heartbeat was taken as unchanged)."""
    rates = Rates()
    assert rates.update({"topic:/odom": 0}, now=100.0) == {}
    assert rates.update({"topic:/odom": 10, "topic:/rosout": 3}, now=102.0) == {
        "topic:/odom": 5.0,
        "topic:/rosout": 1.5,
    }
    # then nothing more: the average decays (weight 0.3 to the newest interval)
    assert rates.update({"topic:/odom": 20, "topic:/rosout": 3}, now=104.0) == {
        "topic:/odom": 5.0,
        "topic:/rosout": 1.05,
    }


def test_the_first_heartbeat_only_starts_the_count() -> None:
    rates = Rates()
    assert rates.update({"topic:/odom": 50}, now=100.0) == {}
    assert rates.update({"topic:/odom": 60}, now=101.0) == {"topic:/odom": 10.0}
