"""The PhyTrace Unified Data Model: its JSON Schema, validator, ids and timestamps."""

from phytrace_edge.udm.event import format_timestamp, new_event_id
from phytrace_edge.udm.schema import SCHEMA_VERSION, check_event, find_violation, load_schema

__all__ = [
    "SCHEMA_VERSION",
    "check_event",
    "find_violation",
    "format_timestamp",
    "load_schema",
    "new_event_id",
]
