"""``phytrace-edge status``: the queue and the service, for people or as JSON; exit 0
healthy, 1 unhealthy, 3 not running."""

from __future__ import annotations

import argparse
import os
from typing import Any, cast

from phytrace_edge.cli.common import error, print_json
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_NOT_RUNNING, QueueError
from phytrace_edge.incident.figures import IncidentFigures
from phytrace_edge.queue.peek import QueueStats, read_stats
from phytrace_edge.runtime import live_status
from phytrace_edge.runtime.health import Live, Thresholds, exit_code, report, thresholds
from phytrace_edge.runtime.status_documents import (
    ClockSection,
    LinkSection,
    ServiceDocument,
    StatusReport,
)
from phytrace_edge.units import format_bytes

LOGS = False  # status prints, it does not log: the health check starts it every 30 s

NAME = "status"
HELP = "show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON (a stable interface)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing: exit code only")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running."""
    path = str(loaded.settings.queue_path)  # loading fills in its default
    live = live_status.read(path, os.environ)
    try:
        stats = read_stats(path)
    except QueueError:
        if live is None:
            raise
        stats = None  # the file cannot be read (a failing disk): the service can say more
    if stats is None and live is None:
        error(f"no queue at {path}: the bridge never ran with this QUEUE_PATH")
        return EXIT_NOT_RUNNING
    document = report_with_live(path, stats, live, thresholds(loaded.settings))
    if args.json:
        print_json(document)
    elif not args.quiet:
        print(render_status(document))
    return exit_code(document)


def report_with_live(
    path: str, stats: QueueStats | None, live: dict[str, Any] | None, limits: Thresholds
) -> StatusReport:
    """The status document from the queue file and the service's live status file;
    either may be missing (a deleted queue file, a service that never wrote one)."""
    heard = None
    if live is not None:
        heard = Live(cast(ServiceDocument, live), live_status.boottime() - live.get("boottime", 0))
    if stats is None:  # what the service last read of its queue
        assert heard is not None
        now = heard.document.get("heartbeat_at", 0.0) + heard.age_s
        counters = dict(heard.document.get("queue_counters", {}))
        stats = QueueStats(path, counters, None, None, 0, None, 0, read_at=now)
    return report(stats, limits, stats.read_at, heard)


def render_resolution(bands: list[dict[str, Any]]) -> str:
    """The periodic history's resolution by age, e.g. ``older than 2 h: 1 in 4, last
    2 h: all`` (important events are always all there)."""
    parts = []
    for band in bands:
        newest, oldest = band["newest_age_s"], band["oldest_age_s"]
        span = (
            f"last {format_age(oldest)}"
            if newest < 60
            else f"{format_age(newest)}-{format_age(oldest)} ago"
        )
        parts.append(f"{span}: {band['keeps']}")
    return ", ".join(parts)


def format_age(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 60:.0f} min" if seconds >= 60 else f"{seconds:.0f} s"


def render_status(d: StatusReport) -> str:
    """The status document as a table for people."""
    state = "HEALTHY" if d["healthy"] else ("UNHEALTHY" if d["problems"] else "NOT RUNNING")
    service, queue = d["service"], d["queue"]
    lines = [f"phytrace-edge status: {state}"]
    if d["heartbeat_age_s"] is None:
        lines.append("  service      never ran with this queue")
    else:
        verb = "running" if d["running"] else "not running"
        lines.append(
            f"  service      {verb} (pid {service.get('pid')}, {service.get('version')}, input "
            f"{service.get('input')}, {service.get('source_id')} -> "
            f"{service.get('endpoint_host')}), heartbeat {d['heartbeat_age_s']:.1f} s ago"
        )
    oldest = "" if queue["oldest_age_s"] is None else f", oldest {queue['oldest_age_s']:.1f} s"
    lines.append(
        f"  queue        {queue['depth']:,} event(s), {format_bytes(queue['held_bytes'])} held "
        f"of {format_bytes(queue['effective_cap_bytes'])} ({queue['cap_limited_by']} limit, "
        f"{queue['fill']:.0%}; files {format_bytes(queue['bytes'])}){oldest}  {queue['path']}"
    )
    unexpected = d["unexpected_answers"]
    lines.append(
        f"  sent         {d['sent_total']} in total, {d['send_rate_eps']:.1f} events/s, last "
        f"success {d['last_success_at'] or 'never'}"
        # answers on which nothing was deleted: a captive portal, or PhyCloud miscounting
        + (f"; {unexpected} unexpected answer(s), batches kept" if unexpected else "")
    )
    if (link := render_link(d["link"])) is not None:
        lines.append(f"  link         {link}")
    if d["exported_total"]:
        lines.append(f"  exported     {d['exported_total']} in hand-carry files (export)")
    lanes = d["lanes"]
    if lanes["live_events_sent"]:
        lag = lanes["live_lag_s"]
        lines.append(
            f"  lanes        live {lanes['live_events_sent']} sent (newest at PhyCloud "
            f"{lag:.1f} s old), backfill {lanes['backfill_events_sent']} sent"
        )
    if d["resolution"]:
        lines.append(f"  history      {render_resolution(d['resolution'])}")
    if d["last_error"]:
        lines.append(f"  last error   {d['last_error']} at {d['last_error_at']}")
    drops = ", ".join(f"{reason} {n}" for reason, n in d["drops"].items()) or "none"
    lines.append(f"  drops        {drops}")
    if (clock := render_clock(d["clock"])) is not None:
        lines.append(f"  clock        {clock}")
    lines.append(
        f"  dead letters {d['dead_letters']}"
        + ("  (phytrace-edge dead-letters list)" if d["dead_letters"] else "")
    )
    if (incidents := render_incidents(d["incidents"])) is not None:
        lines.append(f"  incidents    {incidents}")
    for topic, t in d["topics"].items():
        age = t.get("last_seen_age_s")
        seen = "" if age is None else f", last {age:.1f} s ago"
        lines.append(
            f"  {topic:<16} {t['rate_hz']:.1f} Hz, {t['received']} received{seen}"
            + "".join(f", {note}" for note in topic_notes(t))
        )
    storage = d["storage"]
    if storage["backlog"] or storage["commit_max_s"]:
        lines.append(
            f"  disk         {storage['backlog']} event(s) waiting in memory, last commit "
            f"{_seconds(storage['commit_s'])}, slowest {_seconds(storage['commit_max_s'])} "
            "in the last minute"
        )
    a = d["accounting"]
    lines.append(
        f"  accounting   built {a['built']} = delivered {a['delivered']}"
        + (f" + exported {a['exported']}" if a["exported"] else "")
        + f" + queued {a['queued']} + dead-lettered {a['dead_lettered']}"
        + f" + dropped {sum(a['dropped'].values())} + in memory {a['in_memory']}"
        + ("" if a["balanced"] else "  (DOES NOT ADD UP)")
        + (" (at the last heartbeat)" if d["running"] else "")
    )
    lines += [f"  warning: {warning}" for warning in d["warnings"]]
    lines += [f"  problem: {problem}" for problem in d["problems"]]
    return "\n".join(lines)


def render_incidents(figures: IncidentFigures) -> str | None:
    """This run's incidents in one line; None when no service ran."""
    if not figures:
        return None
    if not figures.get("enabled"):
        return "recording off (INCIDENT_RECORDING)"
    line = (
        f"{figures.get('recorded', 0)} recorded ({figures.get('parts', 0)} part(s), "
        f"{figures.get('parts_sent', 0)} sent)"
        + (", recording now" if figures.get("recording") else "")
        + f"; window {format_bytes(figures.get('buffer_bytes', 0))} of "
        + f"{format_bytes(figures.get('buffer_max_bytes', 0))}"
    )
    lost = [
        f"{figures.get(key, 0)} {what}"
        for key, what in (
            ("rate_limited", "trigger(s) rate-limited"),
            ("samples_dropped", "sample(s) pushed out of the window"),
            ("parts_dead_lettered", "part(s) refused by PhyCloud"),
        )
        if figures.get(key, 0)
    ]
    return line + ("; " + ", ".join(lost) if lost else "")


def render_link(link: LinkSection) -> str | None:
    """The way to PhyCloud when it is not the plain one: a proxy, a client certificate."""
    parts = []
    if link.get("proxy"):
        parts.append(f"through proxy {link['proxy']}")
    if link.get("client_cert"):
        left = link.get("client_cert_expires_in_s")
        days = "" if left is None else f", expires in {left / 86400:.0f} days"
        parts.append(f"client certificate {link['client_cert']}{days}")
    if link.get("api_key_from", "PHYCLOUD_API_KEY") != "PHYCLOUD_API_KEY":
        parts.append(f"key from {link['api_key_from']}")
    return "; ".join(parts) or None


def render_clock(clock: ClockSection) -> str | None:
    """The wall clock, when there is something to say: not synchronized (a robot
    without a real-time clock, before NTP), or a step seen."""
    parts = []
    if clock["synchronized"] is False:
        parts.append("not known to be synchronized (adjtimex)")
    if clock["last_step_s"] is not None:
        parts.append(f"last step {clock['last_step_s']:+.1f} s at {clock['last_step_at']}")
    return "; ".join(parts) or None


def topic_notes(t: dict[str, Any]) -> list[str]:
    """What else is worth a glance about a topic: why it is silent or broken, and what
    became of an extra topic's or /rosout's messages."""
    reasons = t.get("rejected", {})
    # a message with its text repaired was kept: not a reject (an extra topic counts
    # it among its own figures)
    repaired = reasons.get("text_repaired", 0) + t.get("text_repaired", 0)
    rejected = sum(reasons.values()) - reasons.get("text_repaired", 0)
    notes = [f"{rejected} rejected"] if rejected else []
    if repaired:
        notes.append(f"{repaired} with text repaired")
    if t.get("publishers") == 0:
        notes.append("no publisher")
    if t.get("qos_incompatible"):
        notes.append(f"QoS incompatible with {t['qos_incompatible']} publisher(s)")
    if t.get("type_unknown"):
        notes.append(f"type {t['type_unknown']} not installed here")
    if t.get("skipped"):
        notes.append(f"skipped: {t['skipped']}")
    for key, label in (
        ("events", "events"),
        ("records", "log records"),
        ("suppressed", "held back"),
    ):
        if t.get(key):
            notes.append(f"{t[key]} {label}")
    return notes


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f} s"
