"""The two documents between the running service and ``status``, typed.

``ServiceDocument`` is what the heartbeat writes into the queue file every few
seconds (``heartbeat.service_document``); ``StatusReport`` is what ``status`` makes of
it and of the queue (``health.report``): the JSON of ``status --json``, the text of
``status``, and the body of the ``bridge.health`` events. A document written by an
older bridge may lack keys, so readers use ``.get`` on ``ServiceDocument``; mypy holds
every key name to these declarations.
"""

# No `from __future__ import annotations` here: TypedDict would compile each string
# annotation at import, a millisecond on the start-up path of `status`.
from typing import Any, TypedDict


class SenderFigures(TypedDict, total=False):
    """``SendStats.as_dict()`` and the send rate."""

    events_sent: int
    batches_sent: int
    bytes_sent: int
    retries: int
    batches_split: int
    dead_lettered: int
    auth_failures: int
    unexpected_answers: int
    last_success_at: float | None
    last_error: str | None
    last_error_class: str | None
    last_error_at: float | None
    last_status: int | None
    live_events_sent: int
    backfill_events_sent: int
    newest_delivered_at: float | None
    queue_errors: int
    last_queue_error: str | None
    last_queue_error_at: float | None
    send_rate_eps: float


class StageFigures(TypedDict, total=False):
    restarts: int
    progress_age_s: float | None
    stall_after_s: float
    failed: str | None


class ServiceDocument(TypedDict, total=False):
    pid: int
    version: str
    started_at: float
    input: str
    source_id: str
    endpoint_host: str
    sender: SenderFigures
    topics: dict[str, dict[str, Any]]
    stages: dict[str, StageFigures]
    events_built: int
    writer_dropped: int


class QueueSection(TypedDict):
    path: str
    depth: int
    bytes: int
    cap_bytes: int
    fill: float
    oldest_age_s: float | None
    quarantined: str | None
    damaged: str | None


class Lanes(TypedDict):
    live_events_sent: int
    backfill_events_sent: int
    live_lag_s: float | None
    backlog_oldest_age_s: float | None


class ClockSection(TypedDict):
    synchronized: bool | None  # the kernel's word at the queue's last record
    last_step_s: float | None  # the last step of the wall clock seen, + forward
    last_step_at: str | None


class StatusReport(TypedDict):
    healthy: bool
    running: bool
    problems: list[str]
    heartbeat_age_s: float | None
    service: dict[str, Any]  # pid, version, input, source_id, endpoint_host, started_at
    queue: QueueSection
    lanes: Lanes
    resolution: list[dict[str, Any]]
    drops: dict[str, int]
    dead_letters: int
    queued_total: int
    sent_total: int
    exported_total: int
    send_rate_eps: float
    last_success_at: str | None
    last_error: str | None
    last_error_class: str | None
    last_error_at: str | None
    retries: int
    batches_split: int
    auth_failures: int
    queue_errors: int
    events_built: int
    thread_restarts: dict[str, int]
    stages: dict[str, StageFigures]
    topics: dict[str, dict[str, Any]]
    clock: ClockSection
