"""The status verdict: a pure function of the queue's stats and the service's last
heartbeat (runtime/health.py), on known inputs."""

from __future__ import annotations

from typing import cast, get_type_hints

from phytrace_edge.incident.figures import IncidentFigures
from phytrace_edge.queue.peek import QueueStats, ServiceState
from phytrace_edge.runtime.health import Live, Thresholds, accounting, exit_code, report
from phytrace_edge.runtime.heartbeat import Moment, service_document
from phytrace_edge.runtime.options import ServiceOptions
from phytrace_edge.runtime.status_documents import (
    Lanes,
    QueueSection,
    ServiceDocument,
    StatusReport,
)
from phytrace_edge.units import GIB

NOW = 1_800_000_000.0
LIMITS = Thresholds(
    health_stale_s=15, no_progress_s=300, queue_warn_fraction=0.8, queue_max_bytes=GIB
)


WRITER_OK = {
    "backlog": 0,
    "backlog_max": 10_000,
    "oldest_backlog_age_s": None,
    "writes_failing_s": None,
    "write_attempts_failed": 0,
    "last_write_error": None,
    "commit_s": 0.01,
    "commit_max_s": 0.02,
}


def stats(heartbeat_age: float | None = 1.0, **document) -> QueueStats:
    service = (
        None
        if heartbeat_age is None
        else ServiceState(NOW - heartbeat_age, True, {"sender": {}, **document})
    )
    return QueueStats("/q.db", {"depth": 0}, None, None, 4096, None, 0, service)


def stage(age: float, restarts: int = 0, **extra) -> dict:
    return {"progress_age_s": age, "restarts": restarts, "stall_after_s": 30.0, **extra}


def test_a_running_service_with_every_stage_moving_is_healthy() -> None:
    doc = report(
        stats(stages={"sender": stage(0.5), "writer": stage(1.0, restarts=2)}), LIMITS, NOW
    )
    assert doc["healthy"] and exit_code(doc) == 0
    assert doc["thread_restarts"] == {"sender": 0, "writer": 2}


def test_a_stage_without_progress_is_named_with_how_long() -> None:
    doc = report(stats(stages={"sender": stage(95.0), "writer": stage(1.0)}), LIMITS, NOW)
    assert not doc["healthy"] and exit_code(doc) == 1
    assert doc["problems"] == ["stage sender has made no progress for 95 s"]


def test_a_stage_within_its_own_bound_is_not_stuck() -> None:
    # a request may take up to HTTP_TIMEOUT_S: the stall bound is the larger of the two
    doc = report(stats(stages={"sender": stage(20.0)}), LIMITS, NOW)
    assert doc["healthy"], doc["problems"]


def test_a_stage_that_could_not_be_kept_alive_is_reported() -> None:
    failed = stage(70.0, restarts=5, failed="thread sender failed 5 times in 60 s")
    doc = report(stats(stages={"sender": failed}), LIMITS, NOW)
    assert doc["problems"] == [
        "stage sender could not be kept alive: thread sender failed 5 times in 60 s"
    ]


def test_stages_of_a_stopped_service_are_not_judged() -> None:
    doc = report(stats(heartbeat_age=None), LIMITS, NOW)
    assert doc["problems"] == [] and not doc["running"] and exit_code(doc) == 3
    doc = report(stats(heartbeat_age=120.0, stages={"sender": stage(500.0)}), LIMITS, NOW)
    assert doc["problems"] == ["heartbeat is 120 s old: the service hung or died"]


def test_a_queue_error_since_the_last_success_is_a_problem_until_a_send_succeeds() -> None:
    error = {"last_queue_error": "database is locked", "last_queue_error_at": NOW - 3}
    locked = report(stats(sender={"last_success_at": NOW - 10, **error}), LIMITS, NOW)
    assert locked["problems"] == ["the sender cannot use the queue: database is locked"]
    recovered = report(stats(sender={"last_success_at": NOW - 1, **error}), LIMITS, NOW)
    assert recovered["healthy"]
    old = {"last_queue_error": "database is locked", "last_queue_error_at": NOW - 60}
    assert report(stats(sender={"last_success_at": NOW - 100, **old}), LIMITS, NOW)["healthy"]


def test_status_names_what_is_wrong_with_a_silent_topic() -> None:
    from phytrace_edge.cli.status import render_status

    topics = {
        "/scan": {"received": 0, "rate_hz": 0.0, "publishers": 1, "qos_incompatible": 2},
        "/gps/fix": {"received": 0, "rate_hz": 0.0, "publishers": 0},
        "/acme/drive": {"received": 0, "rate_hz": 0.0, "type_unknown": "acme_msgs/msg/Drive"},
        "/rosout": {"received": 40, "rate_hz": 1.0, "records": 12, "suppressed": 28},
    }
    text = render_status(report(stats(topics=topics), LIMITS, NOW))
    lines = {line.split()[0]: line for line in text.splitlines() if line.startswith("  /")}
    assert lines["/scan"].endswith("0 received, QoS incompatible with 2 publisher(s)")
    assert lines["/gps/fix"].endswith("0 received, no publisher")
    assert "type acme_msgs/msg/Drive not installed here" in lines["/acme/drive"]
    assert lines["/rosout"].endswith("12 log records, 28 held back")


def test_status_and_the_watchdog_judge_a_stage_by_the_same_bound() -> None:
    """With HEALTH_STALE_S raised above the service's stall bound, a stage 45 s without
    progress (bound 30 s) is a problem in status, as it is for the watchdog, which the
    service stops feeding at that bound (both use ``stalled``)."""
    from phytrace_edge.runtime.health import stalled

    patient = Thresholds(
        health_stale_s=60, no_progress_s=300, queue_warn_fraction=0.8, queue_max_bytes=GIB
    )
    doc = report(stats(stages={"sender": stage(45.0)}), patient, NOW)
    assert doc["problems"] == ["stage sender has made no progress for 45 s"]
    assert stalled(45.0, 30.0) and not stalled(30.0, 30.0) and not stalled(None, 30.0)


def test_unexpected_answers_are_in_status_and_on_its_sent_line() -> None:
    from phytrace_edge.cli.status import render_status

    doc = report(stats(sender={"unexpected_answers": 4, "last_success_at": NOW - 1}), LIMITS, NOW)
    assert doc["unexpected_answers"] == 4
    sent = next(line for line in render_status(doc).splitlines() if line.startswith("  sent"))
    assert sent.endswith("; 4 unexpected answer(s), batches kept")
    quiet = report(stats(sender={"last_success_at": NOW - 1}), LIMITS, NOW)
    assert quiet["unexpected_answers"] == 0 and "unexpected" not in render_status(quiet)


def test_the_status_report_has_exactly_the_declared_keys() -> None:
    """StatusReport (runtime/status_documents.py) is what status --json prints, key for key."""
    document = report(stats(sender={"last_success_at": NOW - 1}), LIMITS, NOW)
    assert set(document) == set(get_type_hints(StatusReport))
    assert set(document["queue"]) == set(get_type_hints(QueueSection))
    assert set(document["lanes"]) == set(get_type_hints(Lanes))


def test_the_heartbeat_writes_only_declared_keys() -> None:
    options = ServiceOptions("sim", "bot", "amr", "127.0.0.1:9", 5.0, 5.0)
    ledger = {"built": 7, "written": 7, "in_memory": 0, "dropped": {}}
    moment = Moment(ledger, WRITER_OK, {"state": "ok"}, {"queued_total": 7}, {}, NOW, True, 1.0)
    incidents: IncidentFigures = {"enabled": True, "recorded": 1}
    document = service_document(options, {"events_sent": 3}, {}, {}, 7, NOW, moment, incidents)
    assert set(document) == set(get_type_hints(ServiceDocument))
    assert report(stats(**document), LIMITS, NOW)["events_built"] == 7
    assert report(stats(**document), LIMITS, NOW)["incidents"] == incidents


def live(age_s: float, **document) -> Live:
    """The service's live status file, ``age_s`` old, saying it runs."""
    return Live(cast(ServiceDocument, {"sender": {}, "running": True, **document}), age_s)


def test_failing_writes_are_named_from_the_live_status_not_hung_or_died() -> None:
    # the queue's heartbeat row is 40 s old (its volume fails); the live file is fresh
    failing = {**WRITER_OK, "writes_failing_s": 38.0, "backlog": 1900}
    failing["last_write_error"] = "queue /q.db: disk I/O error: read-only file system"
    doc = report(stats(heartbeat_age=40.0), LIMITS, NOW, live(1.0, writer=failing))
    assert doc["running"] and exit_code(doc) == 1
    assert doc["problems"] == [
        "queue writes have failed for 38 s: queue /q.db: disk I/O error: read-only file "
        "system; 1900 event(s) wait in memory (at most 10000)"
    ]
    assert doc["storage"]["backlog"] == 1900 and doc["storage"]["writes_failing_s"] == 38.0


def test_a_stale_live_status_is_hung_or_died_as_the_row_says() -> None:
    doc = report(stats(heartbeat_age=40.0), LIMITS, NOW, live(30.0, writer=WRITER_OK))
    assert not doc["running"]
    assert doc["problems"] == ["heartbeat is 30 s old: the service hung or died"]


def test_a_slow_disk_is_a_warning_then_a_problem_once_events_wait() -> None:
    slow = {**WRITER_OK, "commit_s": 3.0, "commit_max_s": 3.1}
    doc = report(stats(), LIMITS, NOW, live(1.0, writer=slow))
    assert doc["healthy"] and doc["warnings"] == [
        "the queue's disk is slow: a commit took 3.1 s in the last minute (an SD card or "
        "eMMC wearing out?)"
    ]
    waiting = {**slow, "backlog": 400, "oldest_backlog_age_s": 7.5}
    doc = report(stats(), LIMITS, NOW, live(1.0, writer=waiting))
    assert doc["problems"] == [
        "events wait 8 s in memory before they reach the disk (400 waiting; commits take "
        "3.0 s) - the queue's disk is too slow"
    ]


def test_the_queue_file_state_is_a_problem_in_its_own_words() -> None:
    gone = {"state": "folder_gone", "detail": "the queue's folder /q is gone (...)"}
    doc = report(stats(), LIMITS, NOW, live(1.0, writer=WRITER_OK, queue_file=gone))
    assert doc["problems"] == ["the queue's folder /q is gone (...)"]
    assert doc["storage"]["file"] == "folder_gone"


def test_the_accounting_adds_up_and_says_so_when_it_does_not() -> None:
    counters = {
        "queued_total": 100,
        "acked_total": 60,
        "depth": 25,
        "drop:rejected": 5,
        "requeued_total": 2,  # two dead letters put back: queued again
        "drop:unwritable": 8,
        "drop:thinned": 4,
    }
    a = accounting(counters, in_memory=7)
    assert a == {
        "built": 107,
        "delivered": 60,
        "exported": 0,
        "queued": 25,
        "dead_lettered": 3,
        "dropped": {"unwritable": 8, "thinned": 4},
        "in_memory": 7,
        "balanced": True,
    }
    assert not accounting({**counters, "depth": 24}, in_memory=7)["balanced"]


def test_a_running_service_s_accounting_is_read_at_its_heartbeat() -> None:
    moment = {"queued_total": 10, "acked_total": 4, "depth": 6}
    ledger = {"built": 12, "written": 10, "in_memory": 2, "dropped": {}}
    doc = report(
        stats(),  # the file's counters now: depth 0, read later than the heartbeat
        LIMITS,
        NOW,
        live(1.0, writer=WRITER_OK, queue_counters=moment, ledger=ledger),
    )
    assert doc["accounting"]["built"] == 12 and doc["accounting"]["balanced"]


def test_a_refusal_is_a_problem_until_a_request_succeeds_again() -> None:
    tls = "TLS: the certificate of api.example.com is signed by a CA this robot does not trust"
    refused = {"last_refusal": tls, "last_refusal_at": NOW - 5, "last_error_at": NOW - 5}
    doc = report(stats(sender=refused), LIMITS, NOW)
    assert doc["problems"] == [tls] and exit_code(doc) == 1
    doc = report(stats(sender={**refused, "last_success_at": NOW - 1}), LIMITS, NOW)
    assert doc["problems"] == [] and doc["healthy"]


def test_a_refused_key_names_where_the_key_comes_from() -> None:
    sender = {"last_status": 401, "last_refusal": "HTTP 401", "last_refusal_at": NOW - 2}
    link = {"api_key_from": "PHYCLOUD_API_KEY_FILE /etc/phytrace-edge/api_key"}
    doc = report(stats(sender=sender, link=link), LIMITS, NOW)
    assert doc["problems"] == [
        "PhyCloud refuses the API key (HTTP 401) - check PHYCLOUD_API_KEY_FILE "
        "/etc/phytrace-edge/api_key"
    ]
    doc = report(stats(sender=sender), LIMITS, NOW)  # an older bridge's document: no link
    assert doc["problems"] == ["PhyCloud refuses the API key (HTTP 401) - check PHYCLOUD_API_KEY"]


def test_why_sending_fails_is_shown_at_once_and_health_waits_as_for_an_outage() -> None:
    error = "ConnectError: [Errno 111] Connection refused (through proxy http://p:3128)"
    sender = {"last_error": error, "last_error_at": NOW - 3, "last_success_at": NOW - 30}
    doc = report(stats(sender=sender), LIMITS, NOW)
    assert doc["warnings"] == [f"sending fails: {error}"] and doc["healthy"]
    old = {**sender, "last_error_at": NOW - 61}  # a minute without a new error: over
    assert report(stats(sender=old), LIMITS, NOW)["warnings"] == []


def test_a_client_certificate_is_warned_of_before_it_expires() -> None:
    def link_warnings(left_s: float) -> list[str]:
        link = {"client_cert": "/etc/robot.crt", "client_cert_expires_at": NOW + left_s}
        doc = report(stats(link=link), LIMITS, NOW)
        assert doc["link"]["client_cert_expires_in_s"] == round(left_s)
        return doc["warnings"]

    assert link_warnings(30 * 86400) == []
    assert link_warnings(3 * 86400) == [
        "CLIENT_CERT /etc/robot.crt expires in 3.0 days (2027-01-18T08:00:00.000Z): renew it"
    ]
    assert link_warnings(-86400) == [
        "CLIENT_CERT /etc/robot.crt expired on 2027-01-14T08:00:00.000Z (by this robot's "
        "clock): renew it"
    ]
