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

from phytrace_edge.incident.figures import IncidentFigures


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
    last_refusal: str | None
    last_refusal_at: float | None
    live_events_sent: int
    backfill_events_sent: int
    newest_delivered_at: float | None
    queue_errors: int
    last_queue_error: str | None
    last_queue_error_at: float | None
    send_rate_eps: float


class LinkFigures(TypedDict, total=False):
    """How the bridge reaches PhyCloud (``HttpTransport.figures``): never a secret."""

    endpoint: str  # credentials in the URL masked
    proxy: str | None  # the proxy in use, its password masked; None: direct
    trust: str  # the trust store, and CA_BUNDLE when set
    client_cert: str | None
    client_cert_expires_at: float | None  # Unix seconds
    api_key_from: str  # the setting or file the key comes from


class StageFigures(TypedDict, total=False):
    restarts: int
    progress_age_s: float | None
    stall_after_s: float
    failed: str | None


class WriterFigures(TypedDict):
    """How the queue's disk is doing, as the writer sees it (``QueueWriter.figures``)."""

    backlog: int  # events built and waiting in memory for the disk
    backlog_max: int  # beyond it a live input's newest events are dropped
    oldest_backlog_age_s: float | None
    writes_failing_s: float | None  # how long queue writes have failed, None if they work
    write_attempts_failed: int
    last_write_error: str | None
    commit_s: float | None  # the last group commit
    commit_max_s: float | None  # the slowest in the last minute


class LedgerFigures(TypedDict):
    """This run's events at one moment: built = written + in_memory + dropped."""

    built: int
    written: int  # handed to the queue (which counts what its caps did with them)
    in_memory: int
    dropped: dict[str, int]  # before the queue: writer_backlog, unwritable


class QueueFileFigures(TypedDict, total=False):
    """Whether the queue file is still where QUEUE_PATH says (``queue/storage/file_watch.py``)."""

    state: str  # ok, deleted, moved, replaced, folder_gone
    detail: str | None  # what happened and what the bridge did, one line
    open_path: str | None  # where the open file is now (moved), from /proc
    restored: int  # times the file was restored at QUEUE_PATH from the open copy
    volume_free_bytes: int | None


class ServiceDocument(TypedDict, total=False):
    pid: int
    version: str
    started_at: float
    input: str
    source_id: str
    endpoint_host: str
    sender: SenderFigures
    link: LinkFigures
    topics: dict[str, dict[str, Any]]
    stages: dict[str, StageFigures]
    events_built: int
    incidents: IncidentFigures
    writer: WriterFigures
    ledger: LedgerFigures
    queue_file: QueueFileFigures
    queue_counters: dict[str, int]  # the queue's counters at the heartbeat (live status)
    unwritten_counts: dict[str, int]  # counts the queue could not take yet (live status)
    boottime: float  # CLOCK_BOOTTIME at the heartbeat (live status)
    heartbeat_at: float  # queue time at the heartbeat (live status)
    running: bool  # (live status)


class QueueSection(TypedDict):
    path: str
    depth: int
    bytes: int  # of the queue's files on disk
    cap_bytes: int  # QUEUE_MAX_BYTES
    held_bytes: int  # of the events held (the stored_bytes counter)
    effective_cap_bytes: int  # what events may take: of QUEUE_MAX_BYTES or the volume
    cap_limited_by: str  # "QUEUE_MAX_BYTES" or "volume"
    fill: float  # held_bytes / effective_cap_bytes
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


class Accounting(TypedDict):
    """Every event built for this queue, accounted for: built = delivered + exported +
    queued + dead_lettered + sum(dropped) + in_memory."""

    built: int
    delivered: int
    exported: int
    queued: int
    dead_lettered: int
    dropped: dict[str, int]
    in_memory: int
    balanced: bool


class StorageSection(TypedDict):
    """The queue's disk as the running service sees it (None-valued when not running)."""

    writes_failing_s: float | None
    last_write_error: str | None
    backlog: int
    backlog_max: int
    oldest_backlog_age_s: float | None
    commit_s: float | None
    commit_max_s: float | None
    file: str  # ok, deleted, moved, replaced, folder_gone (unknown when not running)
    file_detail: str | None


class LinkSection(LinkFigures, total=False):
    client_cert_expires_in_s: float | None  # by this machine's wall clock


class StatusReport(TypedDict):
    healthy: bool
    running: bool
    problems: list[str]
    warnings: list[str]  # worth a look, not unhealthy (a slow disk)
    heartbeat_age_s: float | None
    service: dict[str, Any]  # pid, version, input, source_id, endpoint_host, started_at
    queue: QueueSection
    link: LinkSection
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
    unexpected_answers: int  # 2xx not PhyCloud's answer, or not accounting for the batch
    queue_errors: int
    events_built: int
    incidents: IncidentFigures  # this run's (empty when no service ran)
    thread_restarts: dict[str, int]
    stages: dict[str, StageFigures]
    topics: dict[str, dict[str, Any]]
    clock: ClockSection
    accounting: Accounting
    storage: StorageSection
