"""Is the bridge healthy? A pure function of what ``status`` read and a few thresholds.

Unhealthy when: the service's heartbeat is stale while it claims to run (hung or
killed); PhyCloud refuses the API key; the queue is above QUEUE_WARN_FRACTION of its
cap; or events are waiting and nothing was sent for HEALTH_NO_PROGRESS_S.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from phytrace_edge.runtime.state import Snapshot
from phytrace_edge.udm.event import format_timestamp

HEALTHY, UNHEALTHY, NOT_RUNNING = 0, 1, 3


@dataclass(frozen=True)
class Thresholds:
    stale_after_s: float
    no_progress_s: float
    queue_warn_fraction: float
    queue_max_bytes: int


def _iso(unix_s: float | None) -> str | None:
    return None if unix_s is None else format_timestamp(unix_s)


def report(snapshot: Snapshot, limits: Thresholds, now: float, path: str) -> dict[str, Any]:
    """The status document (docs/operations.md lists its keys) with ``healthy`` and
    ``problems``."""
    counters, service = snapshot.counters, snapshot.service
    sender = service.get("sender", {})
    heartbeat_age = None if snapshot.heartbeat_at is None else round(now - snapshot.heartbeat_at, 1)
    oldest_age = (
        None if snapshot.oldest_queued_at is None else round(now - snapshot.oldest_queued_at, 1)
    )
    depth = counters.get("depth", 0)
    last_success = sender.get("last_success_at")
    running = (
        snapshot.running and heartbeat_age is not None and heartbeat_age <= limits.stale_after_s
    )

    problems = []
    if snapshot.running and not running:
        problems.append(f"heartbeat is {heartbeat_age:.0f} s old: the service hung or died")
    if sender.get("last_status") in (401, 403) and (sender.get("last_error_at") or 0) > (
        last_success or 0
    ):
        problems.append(
            f"PhyCloud refuses the API key (HTTP {sender['last_status']}) - check PHYCLOUD_API_KEY"
        )
    fill = snapshot.file_bytes / limits.queue_max_bytes if limits.queue_max_bytes else 0.0
    if fill > limits.queue_warn_fraction:
        problems.append(f"queue is {fill:.0%} of QUEUE_MAX_BYTES")
    waited = oldest_age is not None and oldest_age > limits.no_progress_s
    idle = last_success is None or now - last_success > limits.no_progress_s
    if depth and waited and idle:
        problems.append(
            f"{depth} event(s) waiting and nothing sent for over "
            f"{limits.no_progress_s:.0f} s (last error: {sender.get('last_error')})"
        )
    if snapshot.quarantined:
        problems.append(f"a corrupt queue file was moved aside: {snapshot.quarantined}")

    return {
        "healthy": not problems and running,
        "running": running,
        "problems": problems,
        "heartbeat_age_s": heartbeat_age,
        "service": {
            key: service.get(key)
            for key in ("pid", "version", "input", "source_id", "endpoint_host")
            if key in service
        }
        | {"started_at": _iso(service.get("started_at"))},
        "queue": {
            "path": path,
            "depth": depth,
            "bytes": snapshot.file_bytes,
            "cap_bytes": limits.queue_max_bytes,
            "fill": round(fill, 4),
            "oldest_age_s": oldest_age,
            "quarantined": snapshot.quarantined,
        },
        "drops": {k[5:]: v for k, v in counters.items() if k.startswith("drop:") and v},
        "dead_letters": counters.get("dead_letters", 0),
        "queued_total": counters.get("queued_total", 0),
        "sent_total": counters.get("acked_total", 0),
        "send_rate_eps": sender.get("send_rate_eps", 0.0) if running else 0.0,
        "last_success_at": _iso(last_success),
        "last_error": sender.get("last_error"),
        "last_error_at": _iso(sender.get("last_error_at")),
        "retries": sender.get("retries", 0),
        "batches_split": sender.get("batches_split", 0),
        "auth_failures": sender.get("auth_failures", 0),
        "events_built": service.get("events_built", 0),
        "topics": service.get("topics", {}),
    }


def exit_code(document: dict[str, Any]) -> int:
    if document["problems"]:
        return UNHEALTHY
    return HEALTHY if document["running"] else NOT_RUNNING
