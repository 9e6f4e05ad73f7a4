"""Incidents as the stub's page sees them: the parts of one ``incident`` (UDM 1.3.0)
put back together.

An incident arrives in parts (``incident.part`` of ``incident.parts``), each a slice
of the window in time, each carrying the incident's id, trigger and window. The store
keeps each part as the event it is and, beside it, the part's summary (:func:`part_row`:
no samples, only how many of each topic), so that listing incidents reads a few
hundred bytes a part, not the megabytes of their samples. :func:`merge` makes one
incident's entry of the list from its parts' summaries, with the stretches of the
window that missing parts would fill (``gaps``, so that the page breaks its lines
there instead of joining across them); the samples themselves are joined per topic only
for the one incident asked for (``StubStore.incident``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import orjson

EVENT_TYPE_INCIDENT = "incident"
OPTIONAL = ("triggers", "dropped", "cut_short")


def part_row(event: dict[str, Any]) -> tuple[str, int, int, str, str, str, str] | None:
    """``(incident id, part, parts, source_id, trigger at, summary JSON, event_id)`` of
    an ``incident`` event, or None for any other event. The summary holds no samples:
    their counts by topic and the first and last sample's ``t`` of the part."""
    body = event.get("incident")
    if event.get("event_type") != EVENT_TYPE_INCIDENT or not isinstance(body, dict):
        return None
    trigger = body.get("trigger") or {}
    samples = body.get("samples") or {}
    stamps = [str(s.get("t")) for items in samples.values() for s in items if s.get("t")]
    summary: dict[str, Any] = {
        "trigger": trigger,
        "window": body.get("window") or {},
        "sample_counts": {topic: len(items) for topic, items in samples.items()},
        "first_t": min(stamps, default=None),
        "last_t": max(stamps, default=None),
        "captured_at": event.get("captured_at"),
        **{key: body[key] for key in OPTIONAL if key in body},
    }
    return (
        str(body.get("id")),
        int(body.get("part", 1)),
        int(body.get("parts", 1)),
        str(event.get("source_id")),
        str(trigger.get("at", "")),
        orjson.dumps(summary).decode(),
        str(event.get("event_id")),
    )


def merge(
    incident_id: str, source_id: str, received_parts: Iterable[tuple[int, int, str]]
) -> dict[str, Any]:
    """One incident's entry from its received parts' ``(part, parts, summary JSON)``:
    what it is (trigger, window), which parts came and which are missing, where in the
    window the missing ones belong, and how many samples of each topic came."""
    got: dict[int, dict[str, Any]] = {}
    expected = 1
    for part, parts, summary_json in received_parts:
        got[part] = orjson.loads(summary_json)
        expected = max(expected, parts, part)
    first = got[min(got)] if got else {}
    counts: dict[str, int] = {}
    for summary in got.values():
        for topic, count in summary.get("sample_counts", {}).items():
            counts[topic] = counts.get(topic, 0) + count
    missing = [n for n in range(1, expected + 1) if n not in got]
    window = first.get("window", {})
    return {
        "id": incident_id,
        "source_id": source_id,
        "trigger": first.get("trigger", {}),
        "window": window,
        "parts": expected,
        "parts_received": len(got),
        "missing_parts": missing,
        "complete": not missing,
        "gaps": _gaps(missing, got, window),
        "sample_counts": dict(sorted(counts.items())),
        "captured_at": first.get("captured_at"),
        **{key: first[key] for key in OPTIONAL if key in first},
    }


def _gaps(
    missing: list[int], got: dict[int, dict[str, Any]], window: dict[str, Any]
) -> list[dict[str, Any]]:
    """Per run of consecutive missing parts: ``{"parts", "from", "to"}``, from the last
    sample before them (else the window's start) to the first after (else its end)."""
    runs: list[list[int]] = []
    for n in missing:
        if runs and runs[-1][-1] == n - 1:
            runs[-1].append(n)
        else:
            runs.append([n])
    gaps = []
    for run in runs:
        before = [got[n]["last_t"] for n in sorted(got) if n < run[0] and got[n].get("last_t")]
        after = [got[n]["first_t"] for n in sorted(got) if n > run[-1] and got[n].get("first_t")]
        gaps.append(
            {
                "parts": run,
                "from": before[-1] if before else window.get("start"),
                "to": after[0] if after else window.get("end"),
            }
        )
    return gaps
