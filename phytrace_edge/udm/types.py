"""The UDM event as a type: one TypedDict per event type, the shape the JSON Schema
(``udm-1.3.0.schema.json``) gives it, so that mypy follows the event from the builder
to the queue (docs/udm.md has the field-by-field table).

An event stays a plain dict at run time: the queue encodes it with orjson as it is,
and the schema check (``udm/schema.py``) holds the contents that types cannot (patterns,
bounds). A domain's content (``location``, ``motion``, ...) is typed as ``Domain``: its
fields are the schema's and the assembler's (``builder/assemble.py``).

``Built`` is what a stage hands the queue: an event and its class (*important* events
are never thinned from a backlog and go first; docs/udm.md, "Event classes").
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple, TypedDict

Domain = dict[str, Any]


class _IdentityRequired(TypedDict):
    source_id: str
    source_type: str


class UdmIdentity(_IdentityRequired, total=False):
    """Who the events are about: ``source_id`` and ``source_type``, and FLEET_ID and
    SITE_ID when they are set."""

    fleet_id: str
    site_id: str


class WallClock(TypedDict, total=False):
    """The stamping clock, when there is something to say of it (docs/udm.md, "Time")."""

    synchronized: bool
    corrected_by_s: float
    last_step_s: float
    last_step_at: str


class _Clock(TypedDict):
    clock: Literal["epoch", "sim", "non_epoch", "none"]


class Stamp(_Clock, total=False):
    """A message's header stamp: its clock, and the stamp as a timestamp (``epoch``)
    or in seconds (``sim``, ``non_epoch``); none for a zero stamp."""

    stamp: str
    stamp_s: float


class Envelope(TypedDict):
    """What every event has."""

    event_id: str
    event_type: str
    schema_version: str
    captured_at: str
    source_id: str
    source_type: str
    identity: UdmIdentity


class PeriodicEvent(Envelope, total=False):
    """``telemetry.periodic``: one per sample tick, a domain for each fresh topic."""

    wall_clock: WallClock
    location: Domain
    motion: Domain
    power: Domain
    operational: Domain
    navigation: Domain
    perception: Domain
    actuators: Domain
    payload: Domain


TopicMode = Literal["sample", "on_change"]


class _TopicFields(Envelope):
    topic: str
    type: str
    mode: TopicMode
    data: dict[str, Any]
    age_s: float
    clock: Literal["epoch", "sim", "non_epoch", "none"]


class TopicEvent(_TopicFields, total=False):
    """``telemetry.topic``: one message of a TOPICS_EXTRA topic, as JSON."""

    wall_clock: WallClock
    stamp: str
    stamp_s: float


class _LogFields(Envelope):
    level: str
    logger: str
    message: str
    clock: Literal["epoch", "sim", "non_epoch", "none"]


class LogRecordEvent(_LogFields, total=False):
    """``log.record``: one /rosout record at or above ROSOUT_MIN_LEVEL."""

    wall_clock: WallClock
    file: str
    function: str
    line: int
    suppressed: int
    stamp: str
    stamp_s: float


class _HealthFields(Envelope):
    trigger: str
    healthy: bool
    problems: list[str]
    version: str
    uptime_s: float
    queue: dict[str, Any]


class HealthEvent(_HealthFields, total=False):
    """``bridge.health``: the bridge's own state, shipped through its own queue."""

    wall_clock: WallClock
    drops: dict[str, int]
    dead_letters: int
    send_rate_eps: float
    events_sent: int
    retries: int
    last_error_class: str
    thread_restarts: dict[str, int]
    topics: dict[str, dict[str, Any]]
    incidents: dict[str, int]


class _IncidentTriggerFields(TypedDict):
    kind: Literal["diagnostics", "rosout", "topic", "manual"]
    message: str
    at: str


class IncidentTrigger(_IncidentTriggerFields, total=False):
    """What opened the incident (the first trigger; later ones only extended it)."""

    topic: str
    level: str


class IncidentWindow(TypedDict):
    """The window's first and last moment: INCIDENT_BEFORE_S before the trigger to
    INCIDENT_AFTER_S after the last trigger that extended it."""

    start: str
    end: str


class _IncidentFields(TypedDict):
    id: str
    part: int
    parts: int
    trigger: IncidentTrigger
    window: IncidentWindow
    samples: dict[str, list[dict[str, Any]]]


class Incident(_IncidentFields, total=False):
    """One part of an incident: the samples of the window topics in a slice of the
    window, keyed by topic, each ``{"t": ..., **reading}`` in time order."""

    triggers: int
    dropped: dict[str, int]
    cut_short: bool


class _IncidentEventFields(Envelope):
    incident: Incident


class IncidentEvent(_IncidentEventFields, total=False):
    """``incident``: full-rate data around a trigger, in parts (UDM 1.3.0)."""

    wall_clock: WallClock


UdmEvent = PeriodicEvent | TopicEvent | LogRecordEvent | HealthEvent | IncidentEvent


class Built(NamedTuple):
    """An event and its class, as a stage hands it to the queue."""

    event: UdmEvent
    important: bool = False
