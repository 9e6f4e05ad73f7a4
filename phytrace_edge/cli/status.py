"""``phytrace-edge status``: the queue and the service, for people or as JSON; exit 0
healthy, 1 unhealthy, 3 not running."""

from __future__ import annotations

import argparse
from typing import Any

from phytrace_edge.cli.common import error, print_json
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_NOT_RUNNING
from phytrace_edge.queue.inspect import read_stats
from phytrace_edge.runtime.documents import ClockSection, StatusReport
from phytrace_edge.runtime.health import exit_code, report, thresholds
from phytrace_edge.units import format_bytes

LOGS = False  # status prints, it does not log: the health check starts it every 30 s

NAME = "status"
HELP = "show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON (a stable interface)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing: exit code only")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running."""
    path = loaded.settings.queue_path  # loading fills in its default
    stats = read_stats(str(path))
    if stats is None:
        error(f"no queue at {path}: the bridge never ran with this QUEUE_PATH")
        return EXIT_NOT_RUNNING
    document = report(stats, thresholds(loaded.settings), stats.read_at)
    if args.json:
        print_json(document)
    elif not args.quiet:
        print(render_status(document))
    return exit_code(document)


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
        f"  queue        {queue['depth']} event(s), {format_bytes(queue['bytes'])} of "
        f"{format_bytes(queue['cap_bytes'])} ({queue['fill']:.0%}){oldest}  {queue['path']}"
    )
    lines.append(
        f"  sent         {d['sent_total']} in total, {d['send_rate_eps']:.1f} events/s, last "
        f"success {d['last_success_at'] or 'never'}"
    )
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
    for topic, t in d["topics"].items():
        age = t.get("last_seen_age_s")
        seen = "" if age is None else f", last {age:.1f} s ago"
        lines.append(
            f"  {topic:<16} {t['rate_hz']:.1f} Hz, {t['received']} received{seen}"
            + "".join(f", {note}" for note in topic_notes(t))
        )
    lines += [f"  problem: {problem}" for problem in d["problems"]]
    return "\n".join(lines)


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
    rejected = sum(t.get("rejected", {}).values())
    notes = [f"{rejected} rejected"] if rejected else []
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
