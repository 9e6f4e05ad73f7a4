"""A closed incident as UDM ``incident`` events: split into parts under the batch byte
limit, so that each part fits one request (docs/udm.md, "incident"). Pure.

Parts slice the window in time: part 1 holds the oldest samples of every topic, the
last part the newest, each keyed by topic and in time order, so that joining the parts'
``samples`` in part order gives the whole window. Every part carries the incident's id,
trigger and window, so that any one of them says what it belongs to.

Ids are derived, not drawn: the incident's id from the robot, the trigger and its time,
and each part's ``event_id`` from the incident's id and the part. The same bag replayed
twice gives the same incident with the same ids, which PhyCloud takes once.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import orjson

from phytrace_edge.builder.envelope import envelope
from phytrace_edge.incident.triggers import Trigger
from phytrace_edge.udm.event import format_timestamp, format_timestamp_us, new_event_id
from phytrace_edge.udm.types import (
    Incident,
    IncidentEvent,
    IncidentTrigger,
    IncidentWindow,
    UdmIdentity,
)

EVENT_TYPE_INCIDENT = "incident"
PART_HEADROOM_BYTES = 4096  # the envelope, trigger and window of a part, and then some
T_FIELD_BYTES = len(b'"t":"2025-01-15T14:23:01.042315Z",')


@dataclass(frozen=True)
class Sample:
    """One sample of an incident: its topic, when it was received (on the wall clock as
    it is at the close, docs/udm.md) and its reading's JSON."""

    topic: str
    wall_s: float
    json: bytes


@dataclass(frozen=True)
class ClosedIncident:
    """An incident whose window has ended: its trigger, its window on the input's
    timeline, the samples in it (oldest first) and what it lacks."""

    trigger: Trigger
    start_s: float
    end_s: float
    start_wall_s: float
    end_wall_s: float
    samples: Sequence[Sample]
    triggers: int = 1
    dropped: dict[str, int] = field(default_factory=dict)  # by topic: the byte bound
    cut_short: bool = False  # closed by a stop before INCIDENT_AFTER_S had passed
    # the trigger's moment on the wall clock at the close (None: ``trigger.wall_s``); the
    # id stays derived from ``trigger.wall_s``, the moment as the trigger was stamped
    trigger_at_wall_s: float | None = None


def incident_id(identity: UdmIdentity, trigger: Trigger) -> str:
    """The incident's id, the same for the same robot, trigger and moment."""
    seed = f"{identity['source_id']}|{trigger.kind}|{trigger.topic}|{trigger.wall_s:.6f}"
    return new_event_id(int(trigger.wall_s * 1000), hashlib.sha256(seed.encode()).digest())


def part_event_id(incident: str, part: int, at_wall_s: float) -> str:
    digest = hashlib.sha256(f"{incident}|part {part}".encode()).digest()
    return new_event_id(int(at_wall_s * 1000), digest)


def incident_events(
    identity: UdmIdentity, closed: ClosedIncident, max_part_bytes: int
) -> list[IncidentEvent]:
    """The incident's parts, each under ``max_part_bytes`` of JSON (a single sample
    larger than that still gets a part of its own)."""
    ident = incident_id(identity, closed.trigger)
    slices = _slices(closed.samples, max(1, max_part_bytes - PART_HEADROOM_BYTES))
    events = []
    for number, part_samples in enumerate(slices, start=1):
        body = Incident(
            id=ident,
            part=number,
            parts=len(slices),
            trigger=_trigger(closed.trigger, closed.trigger_at_wall_s),
            window=IncidentWindow(
                start=format_timestamp(closed.start_wall_s), end=format_timestamp(closed.end_wall_s)
            ),
            samples=_by_topic(part_samples),
        )
        if closed.triggers > 1:
            body["triggers"] = closed.triggers
        if closed.dropped:
            body["dropped"] = dict(closed.dropped)
        if closed.cut_short:
            body["cut_short"] = True
        event_id = part_event_id(ident, number, closed.end_wall_s)
        event: IncidentEvent = {
            **envelope(identity, EVENT_TYPE_INCIDENT, closed.end_wall_s, event_id),
            "incident": body,
        }
        events.append(event)
    return events


def _trigger(trigger: Trigger, at_wall_s: float | None) -> IncidentTrigger:
    at = trigger.wall_s if at_wall_s is None else at_wall_s
    described = IncidentTrigger(kind=trigger.kind, message=trigger.message, at=format_timestamp(at))
    if trigger.topic is not None:
        described["topic"] = trigger.topic
    if trigger.level is not None:
        described["level"] = trigger.level
    return described


def _slices(samples: Sequence[Sample], budget: int) -> list[list[Sample]]:
    """Consecutive runs of samples whose JSON stays within ``budget`` bytes each; at
    least one (an incident with no samples is still one part: its trigger)."""
    slices: list[list[Sample]] = [[]]
    used = 0
    for sample in samples:
        size = len(sample.json) + T_FIELD_BYTES + len(sample.topic) + 8
        if slices[-1] and used + size > budget:
            slices.append([])
            used = 0
        slices[-1].append(sample)
        used += size
    return slices


def _by_topic(samples: Sequence[Sample]) -> dict[str, list[dict[str, Any]]]:
    by_topic: dict[str, list[dict[str, Any]]] = {}
    for sample in samples:
        reading = orjson.loads(sample.json)
        by_topic.setdefault(sample.topic, []).append(
            {"t": format_timestamp_us(sample.wall_s), **reading}
        )
    return by_topic
