"""What the recorder needs to know (the INCIDENT_* settings), light enough for every
command's start: it imports none of the recorder's parts."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.incident.defaults import (
    DEFAULT_INCIDENT_AFTER_S,
    DEFAULT_INCIDENT_BEFORE_S,
    DEFAULT_INCIDENT_BUFFER_MAX_BYTES,
    DEFAULT_INCIDENT_MAX_PER_HOUR,
    DEFAULT_INCIDENT_MAX_S,
    DEFAULT_INCIDENT_TOPICS,
)
from phytrace_edge.incident.triggers import Condition


@dataclass(frozen=True)
class IncidentOptions:
    """The INCIDENT_* settings (docs/configuration.md, "Incident windows")."""

    enabled: bool = True
    topics: tuple[str, ...] = DEFAULT_INCIDENT_TOPICS
    before_s: float = DEFAULT_INCIDENT_BEFORE_S
    after_s: float = DEFAULT_INCIDENT_AFTER_S
    buffer_max_bytes: int = DEFAULT_INCIDENT_BUFFER_MAX_BYTES
    max_per_hour: int = DEFAULT_INCIDENT_MAX_PER_HOUR
    max_s: float = DEFAULT_INCIDENT_MAX_S
    diagnostics_level: str | None = "error"
    rosout_level: str | None = "error"
    conditions: tuple[Condition, ...] = ()
