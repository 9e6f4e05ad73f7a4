"""The sender's figures as status and metrics read them (ship/stats.py), and whose turn
the next request is after an outage (ship/lanes.py): counts that add up over many
calls, the latency histogram's buckets, what kind of failure the last one was."""

from __future__ import annotations

import httpx

from phytrace_edge.errors import TransientSendError
from phytrace_edge.ship.lanes import Lanes
from phytrace_edge.ship.stats import LATENCY_BUCKETS_S, SendStats


def test_the_latency_histogram_is_cumulative_with_inclusive_bounds() -> None:
    stats = SendStats()
    for seconds in (0.005, 0.3, 0.3, 40.0):
        stats.observe_latency(seconds)
    assert (stats.latency_count, stats.latency_sum_s) == (4, 40.605)
    expected = [sum(1 for s in (0.005, 0.3, 0.3) if s <= bound) for bound in LATENCY_BUCKETS_S]
    assert stats.latency_buckets == expected
    assert stats.latency_buckets[0] == 1  # 0.005 is in the 0.005 bucket


def test_deliveries_add_up_by_lane() -> None:
    stats = SendStats()
    stats.delivered("live", 2, newest_queued_at=9.0)
    stats.delivered("live", 3, newest_queued_at=8.0)
    stats.delivered("backfill", 4, newest_queued_at=1.0)
    stats.delivered("backfill", 1, newest_queued_at=2.0)
    assert (stats.live_events_sent, stats.backfill_events_sent) == (5, 5)
    assert stats.newest_delivered_at == 9.0


def test_a_retry_says_its_status_and_the_network_error_under_it() -> None:
    stats = SendStats()
    stats.count_retry(TransientSendError("HTTP 503", 503), at=1.0)
    assert (stats.last_status, stats.last_error_class) == (503, "HTTP 503")
    try:
        try:
            raise httpx.ConnectError("refused")
        except httpx.ConnectError as exc:
            raise TransientSendError("ConnectError: refused") from exc
    except TransientSendError as exc:
        stats.count_retry(exc, at=2.0)
    assert (stats.last_status, stats.last_error_class) == (None, "ConnectError")
    stats.count_retry(TransientSendError("timeout"), at=3.0)
    assert stats.last_error_class == "TransientSendError"
    assert (stats.retries, stats.last_error_at) == (3, 3.0)


def test_after_an_outage_one_request_is_the_live_lanes_then_live_share_rules() -> None:
    lanes = Lanes(0.25, now=100.0)
    lanes.failed(150.0)
    lanes.succeeded()
    assert lanes.live_turn() == 150.0  # the first request after the link came back
    turns = [lanes.live_turn() for _ in range(4)]
    assert turns == [None, None, 150.0, None]  # then a quarter of them
