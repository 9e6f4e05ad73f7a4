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
from phytrace_edge.queue.peek import QueueStats
from phytrace_edge.queue.space.volume import LIMIT_VOLUME
from phytrace_edge.runtime.status_documents import (
    Accounting,
    Lanes,
    LinkFigures,
    LinkSection,
    QueueFileFigures,
    SenderFigures,
    ServiceDocument,
    StageFigures,
    StatusReport,
    StorageSection,
    WriterFigures,
)
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.units import format_bytes

SLOW_DISK_S = 5.0  # events waiting longer than this in memory: not durable in time
SLOW_COMMIT_S = 1.0  # a commit this slow is worth a warning


class Live(NamedTuple):
    """The service's live status file (``runtime/live_status.py``) and its age."""

    document: ServiceDocument
    age_s: float


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


class Heard(NamedTuple):
    """The service's last word: its document, how old it is, whether it said it runs."""

    document: ServiceDocument
    age_s: float | None
    claims_to_run: bool
    from_live: bool = False


def last_heard(stats: QueueStats, now: float, live: Live | None) -> Heard:
    """The fresher of the heartbeat row in the queue and the live status file (which
    the service writes even when the queue's volume fails: ``live_status``)."""
    state = stats.service
    row_age = None if state is None else round(now - state.heartbeat_at, 1)
    if live is not None and (row_age is None or live.age_s <= row_age):
        running = bool(live.document.get("running"))
        return Heard(live.document, round(live.age_s, 1), running, from_live=True)
    if state is None:
        return Heard(cast(ServiceDocument, {}), None, False)
    return Heard(cast(ServiceDocument, state.document), row_age, state.running)


def report(
    stats: QueueStats, limits: Thresholds, now: float, live: Live | None = None
) -> StatusReport:
    """The status document (docs/operations.md lists its keys) with ``healthy`` and
    ``problems``; ``live`` is the service's live status, when there is one."""
    service, heartbeat_age, claims_to_run, from_live = last_heard(stats, now, live)
    sender: SenderFigures = service.get("sender", {})
    oldest_age = None if stats.oldest_queued_at is None else round(now - stats.oldest_queued_at, 1)
    last_success = sender.get("last_success_at")
    running = claims_to_run and heartbeat_age is not None and heartbeat_age <= limits.health_stale_s
    stages: dict[str, StageFigures] = service.get("stages", {})
    writer: WriterFigures | None = service.get("writer") if running else None
    queue_file = service.get("queue_file", {}) if running else {}

    problems = []
    warnings: list[str] = []
    if claims_to_run and not running:
        problems.append(f"heartbeat is {heartbeat_age:.0f} s old: the service hung or died")
    if running:
        problems += _stage_problems(stages, limits.health_stale_s)
        problems += _storage_problems(writer, queue_file)
        warnings += _storage_warnings(writer)
    link: LinkFigures = service.get("link", {})
    wall_now = now + stats.clock.wall_offset
    problems += _link_problems(sender, link, last_success)
    warnings += _link_warnings(sender, link, last_success, now, wall_now) if running else []
    queue_error_at = sender.get("last_queue_error_at") or 0
    if (
        running
        and queue_error_at > (last_success or 0)
        and now - queue_error_at < limits.health_stale_s
    ):
        problems.append(f"the sender cannot use the queue: {sender.get('last_queue_error')}")
    # what the queue holds (not its file, which shrinks only at a VACUUM) against the
    # effective cap: QUEUE_MAX_BYTES, or what the volume can hold when that is less
    cap = stats.effective_cap(limits.queue_max_bytes)
    fill = stats.held_bytes / cap.bytes if cap.bytes else float(stats.held_bytes > 0)
    if fill > limits.queue_warn_fraction:
        problems.append(
            f"queue is {fill:.0%} of its cap ({_limit_name(cap.limited_by)}): "
            f"{format_bytes(stats.held_bytes)} held of {format_bytes(cap.bytes)}"
        )
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

    counters = stats.counters
    stopped_unrecorded = from_live and not claims_to_run and service.get("unwritten_counts")
    if (running or stopped_unrecorded) and service.get("queue_counters"):
        # one moment with the ledger; or a stop whose last counts the queue could not
        # take (the file may be readable only as it was before its WAL: a read-only
        # volume), as the service last read them
        counters = service["queue_counters"]
    in_memory = service.get("ledger", {}).get("in_memory", 0) if running else 0
    return {
        "healthy": not problems and running,
        "running": running,
        "problems": problems,
        "warnings": warnings,
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
            "held_bytes": stats.held_bytes,
            "effective_cap_bytes": cap.bytes,
            "cap_limited_by": cap.limited_by,
            "fill": round(fill, 4),
            "oldest_age_s": oldest_age,
            "quarantined": stats.quarantined,
            "damaged": stats.damaged,
        },
        "link": _link(link, wall_now),
        "lanes": _lanes(sender, oldest_age, now),
        "resolution": list(stats.resolution),
        "drops": {k[5:]: v for k, v in counters.items() if k.startswith("drop:") and v},
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
        "unexpected_answers": sender.get("unexpected_answers", 0),
        "queue_errors": sender.get("queue_errors", 0),
        "events_built": service.get("events_built", 0),
        "incidents": service.get("incidents", {}),
        "thread_restarts": {name: s.get("restarts", 0) for name, s in stages.items()},
        "stages": stages,
        "topics": _topics_now(service.get("topics", {}), heartbeat_age, running),
        "clock": {
            "synchronized": stats.clock.synchronized,
            "last_step_s": stats.clock.last_step_s,
            "last_step_at": _date(stats.clock.last_step_at, stats),
        },
        "accounting": accounting(counters, in_memory),
        "storage": _storage(writer, queue_file),
    }


UNREACHABLE_SHOWN_S = 60.0  # a send error this recent is shown as the cause
CERT_WARNING_S = 14 * 86400.0  # as ship/tls.EXPIRY_WARNING_S (not imported: start-up path)


def _link_problems(
    sender: SenderFigures, link: LinkFigures, last_success: float | None
) -> list[str]:
    """What only the operator can fix on the way to PhyCloud: a refused key, TLS that
    does not verify, a client certificate or a proxy's credentials refused."""
    refused_at = sender.get("last_refusal_at") or 0
    if refused_at <= (last_success or 0):
        return []
    if sender.get("last_status") in (401, 403):
        where = link.get("api_key_from", "PHYCLOUD_API_KEY")
        return [f"PhyCloud refuses the API key (HTTP {sender['last_status']}) - check {where}"]
    return [str(sender.get("last_refusal"))]


def _link_warnings(
    sender: SenderFigures,
    link: LinkFigures,
    last_success: float | None,
    now: float,
    wall_now: float,
) -> list[str]:
    """The cause of a send failing now (PhyCloud unreachable, through which proxy),
    shown at once; and a client certificate about to expire."""
    warnings = []
    error_at = sender.get("last_error_at") or 0
    refused_at = sender.get("last_refusal_at") or 0
    recent = now - error_at < UNREACHABLE_SHOWN_S
    if recent and error_at > (last_success or 0) and error_at > refused_at:
        warnings.append(f"sending fails: {sender.get('last_error')}")
    expires_at = link.get("client_cert_expires_at")
    if expires_at is not None and 0 < expires_at - wall_now < CERT_WARNING_S:
        days = (expires_at - wall_now) / 86400
        warnings.append(
            f"CLIENT_CERT {link.get('client_cert')} expires in {days:.1f} days "
            f"({format_timestamp(expires_at)}): renew it"
        )
    elif expires_at is not None and expires_at <= wall_now:
        warnings.append(
            f"CLIENT_CERT {link.get('client_cert')} expired on {format_timestamp(expires_at)} "
            "(by this robot's clock): renew it"
        )
    return warnings


def _link(link: LinkFigures, wall_now: float) -> LinkSection:
    section = cast(LinkSection, dict(link))
    expires_at = link.get("client_cert_expires_at")
    if expires_at is not None:
        section["client_cert_expires_in_s"] = round(expires_at - wall_now)
    return section


def accounting(counters: dict[str, int], in_memory: int) -> Accounting:
    """Every event built for this queue, accounted for (docs/operations.md, "Nothing
    lost"): built = delivered + exported + queued + dead_lettered + dropped + in_memory.
    ``queued_total`` counts every event built that reached the writer's end: put,
    refused by a full disk, or dropped before the queue (``QueueStore.count_unqueued``)."""
    drops = {k[5:]: v for k, v in counters.items() if k.startswith("drop:") and v}
    # dead letters put back into the queue (``dead-letters requeue``) count as queued
    dead = drops.pop("rejected", 0) - counters.get("requeued_total", 0)
    built = counters.get("queued_total", 0) + in_memory
    delivered, exported = counters.get("acked_total", 0), counters.get("exported_total", 0)
    queued = counters.get("depth", 0)
    return {
        "built": built,
        "delivered": delivered,
        "exported": exported,
        "queued": queued,
        "dead_lettered": dead,
        "dropped": drops,
        "in_memory": in_memory,
        "balanced": built == delivered + exported + queued + dead + sum(drops.values()) + in_memory,
    }


def _storage(writer: WriterFigures | None, queue_file: QueueFileFigures) -> StorageSection:
    w = cast(WriterFigures, writer or {})
    return {
        "writes_failing_s": w.get("writes_failing_s"),
        "last_write_error": w.get("last_write_error"),
        "backlog": w.get("backlog", 0),
        "backlog_max": w.get("backlog_max", 0),
        "oldest_backlog_age_s": w.get("oldest_backlog_age_s"),
        "commit_s": w.get("commit_s"),
        "commit_max_s": w.get("commit_max_s"),
        "file": queue_file.get("state", "ok" if writer is not None else "unknown"),
        "file_detail": queue_file.get("detail"),
    }


def _storage_problems(writer: WriterFigures | None, queue_file: QueueFileFigures) -> list[str]:
    """What keeps events from being made durable, as the running service sees it."""
    problems = []
    if queue_file.get("state", "ok") != "ok":
        problems.append(str(queue_file.get("detail")))
    if writer is None:
        return problems
    failing = writer.get("writes_failing_s")
    if failing is not None:
        problems.append(
            f"queue writes have failed for {failing:.0f} s: {writer.get('last_write_error')}; "
            f"{writer['backlog']} event(s) wait in memory (at most {writer['backlog_max']})"
        )
    elif (waited := writer.get("oldest_backlog_age_s")) is not None and waited > SLOW_DISK_S:
        problems.append(
            f"events wait {waited:.0f} s in memory before they reach the disk "
            f"({writer['backlog']} waiting; commits take {writer.get('commit_s')} s) "
            "- the queue's disk is too slow"
        )
    return problems


def _storage_warnings(writer: WriterFigures | None) -> list[str]:
    slowest = None if writer is None else writer.get("commit_max_s")
    if slowest is not None and slowest >= SLOW_COMMIT_S:
        return [
            f"the queue's disk is slow: a commit took {slowest:.1f} s in the last minute "
            "(an SD card or eMMC wearing out?)"
        ]
    return []


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


def _limit_name(limited_by: str) -> str:
    """Which limit set the effective cap, in words (``volume.Cap.limited_by``)."""
    return "what the volume can hold" if limited_by == LIMIT_VOLUME else limited_by
