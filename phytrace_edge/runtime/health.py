"""Is the bridge healthy? A pure function of what ``status`` read and a few thresholds.

Unhealthy when: the service's heartbeat is stale while it claims to run (hung or
killed); a stage of the service has made no progress for HEALTH_STALE_S, or one could
not be kept alive; PhyCloud refuses the API key; the queue is above
QUEUE_WARN_FRACTION of its cap; or events are waiting and nothing was sent for
HEALTH_NO_PROGRESS_S.

On the start-up path of ``status``: nothing outside the standard library, and its
thresholds are read from the settings here rather than in ``runtime/options.py``, which
imports every stage's options (docs/benchmarks.md, "Start-up").
"""

from typing import Any, NamedTuple, cast

from phytrace_edge.config import Settings
from phytrace_edge.errors import EXIT_NOT_RUNNING, EXIT_OK, EXIT_UNHEALTHY
from phytrace_edge.queue.inspect import QueueStats
from phytrace_edge.runtime.documents import (
    Lanes,
    SenderFigures,
    ServiceDocument,
    StageFigures,
    StatusReport,
)
from phytrace_edge.udm.event import format_timestamp


class Thresholds(NamedTuple):
    """HEALTH_STALE_S, HEALTH_NO_PROGRESS_S, QUEUE_WARN_FRACTION and QUEUE_MAX_BYTES."""

    health_stale_s: float
    no_progress_s: float
    queue_warn_fraction: float
    queue_max_bytes: int


def thresholds(s: Settings) -> Thresholds:
    return Thresholds(
        s.health_stale_s, s.health_no_progress_s, s.queue_warn_fraction, s.queue_max_bytes
    )


def _date(queue_time: float | None, stats: QueueStats) -> str | None:
    """A queue time as the date the wall clock now gives it."""
    return None if queue_time is None else format_timestamp(queue_time + stats.clock.wall_offset)


def report(stats: QueueStats, limits: Thresholds, now: float) -> StatusReport:
    """The status document (docs/operations.md lists its keys) with ``healthy`` and
    ``problems``."""
    state = stats.service
    service = cast(ServiceDocument, state.document if state else {})
    sender: SenderFigures = service.get("sender", {})
    heartbeat_age = None if state is None else round(now - state.heartbeat_at, 1)
    oldest_age = None if stats.oldest_queued_at is None else round(now - stats.oldest_queued_at, 1)
    last_success = sender.get("last_success_at")
    claims_to_run = state is not None and state.running
    running = claims_to_run and heartbeat_age is not None and heartbeat_age <= limits.health_stale_s
    stages: dict[str, StageFigures] = service.get("stages", {})

    problems = []
    if claims_to_run and not running:
        problems.append(f"heartbeat is {heartbeat_age:.0f} s old: the service hung or died")
    if running:
        problems += _stage_problems(stages, limits.health_stale_s)
    if sender.get("last_status") in (401, 403) and (sender.get("last_error_at") or 0) > (
        last_success or 0
    ):
        problems.append(
            f"PhyCloud refuses the API key (HTTP {sender['last_status']}) - check PHYCLOUD_API_KEY"
        )
    queue_error_at = sender.get("last_queue_error_at") or 0
    if (
        running
        and queue_error_at > (last_success or 0)
        and now - queue_error_at < limits.health_stale_s
    ):
        problems.append(f"the sender cannot use the queue: {sender.get('last_queue_error')}")
    fill = stats.file_bytes / limits.queue_max_bytes if limits.queue_max_bytes else 0.0
    if fill > limits.queue_warn_fraction:
        problems.append(f"queue is {fill:.0%} of QUEUE_MAX_BYTES")
    waited = oldest_age is not None and oldest_age > limits.no_progress_s
    idle = last_success is None or now - last_success > limits.no_progress_s
    if stats.depth and waited and idle:
        problems.append(
            f"{stats.depth} event(s) waiting and nothing sent for over "
            f"{limits.no_progress_s:.0f} s (last error: {sender.get('last_error')})"
        )
    if stats.quarantined:
        problems.append(f"a corrupt queue file was moved aside: {stats.quarantined}")
    if stats.damaged:
        problems.append(
            f"the queue file is damaged ({stats.damaged}): restart the bridge to move it aside"
        )

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
        | {"started_at": _date(service.get("started_at"), stats)},
        "queue": {
            "path": stats.path,
            "depth": stats.depth,
            "bytes": stats.file_bytes,
            "cap_bytes": limits.queue_max_bytes,
            "fill": round(fill, 4),
            "oldest_age_s": oldest_age,
            "quarantined": stats.quarantined,
            "damaged": stats.damaged,
        },
        "lanes": _lanes(sender, oldest_age, now),
        "resolution": list(stats.resolution),
        "drops": _drops(stats.drops, service),
        "dead_letters": stats.dead_letters,
        "queued_total": stats.queued_total,
        "sent_total": stats.acked_total,
        "exported_total": stats.exported_total,
        "send_rate_eps": sender.get("send_rate_eps", 0.0) if running else 0.0,
        "last_success_at": _date(last_success, stats),
        "last_error": sender.get("last_error"),
        "last_error_class": sender.get("last_error_class"),
        "last_error_at": _date(sender.get("last_error_at"), stats),
        "retries": sender.get("retries", 0),
        "batches_split": sender.get("batches_split", 0),
        "auth_failures": sender.get("auth_failures", 0),
        "queue_errors": sender.get("queue_errors", 0),
        "events_built": service.get("events_built", 0),
        "thread_restarts": {name: s.get("restarts", 0) for name, s in stages.items()},
        "stages": stages,
        "topics": _topics_now(service.get("topics", {}), heartbeat_age, running),
        "clock": {
            "synchronized": stats.clock.synchronized,
            "last_step_s": stats.clock.last_step_s,
            "last_step_at": _date(stats.clock.last_step_at, stats),
        },
    }


def _lanes(sender: SenderFigures, oldest_age: float | None, now: float) -> Lanes:
    """The two lanes of the drain: what each delivered, how far behind the present the
    newest event PhyCloud holds is (``live_lag_s``), and how old the backfill's
    oldest waiting event is (``backlog_oldest_age_s``)."""
    newest = sender.get("newest_delivered_at")
    return {
        "live_events_sent": sender.get("live_events_sent", 0),
        "backfill_events_sent": sender.get("backfill_events_sent", 0),
        "live_lag_s": None if newest is None else round(max(0.0, now - newest), 1),
        "backlog_oldest_age_s": oldest_age,
    }


def _topics_now(
    topics: dict[str, Any], heartbeat_age: float | None, running: bool
) -> dict[str, Any]:
    """Per-topic figures as of now: when the service is not running, the ages of the
    last messages count from now (not from its last heartbeat), and nothing is heard."""
    if running or heartbeat_age is None:
        return topics
    now = {}
    for topic, figures in topics.items():
        age = figures.get("last_seen_age_s")
        now[topic] = {
            **figures,
            "rate_hz": 0.0,
            "last_seen_age_s": None if age is None else round(age + heartbeat_age, 1),
        }
    return now


def _drops(queue_drops: dict[str, int], service: ServiceDocument) -> dict[str, int]:
    """Drops by reason: the queue's, and the service's hand-off to it (the disk stalled
    so long that the writer fell HANDOFF_MAX_EVENTS behind)."""
    drops = dict(queue_drops)
    if service.get("writer_dropped"):
        drops["writer_backlog"] = service["writer_dropped"]
    return drops


def stalled(progress_age_s: float | None, stall_after_s: float) -> bool:
    """The one rule for a stage that makes no progress: past the service's bound
    (``stall_after_s``, written with each stage), the watchdog is no longer fed and
    ``status`` reports the stage, both at that same bound."""
    return progress_age_s is not None and progress_age_s > stall_after_s


def _stage_problems(stages: dict[str, StageFigures], health_stale_s: float) -> list[str]:
    problems = []
    for name, stage in stages.items():
        age = stage.get("progress_age_s")
        if stage.get("failed"):
            problems.append(f"stage {name} could not be kept alive: {stage['failed']}")
        elif stalled(age, stage.get("stall_after_s", health_stale_s)):
            problems.append(f"stage {name} has made no progress for {age:.0f} s")
    return problems


def exit_code(document: StatusReport) -> int:
    if document["problems"]:
        return EXIT_UNHEALTHY
    return EXIT_OK if document["running"] else EXIT_NOT_RUNNING
