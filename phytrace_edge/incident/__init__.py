"""Incident windows: full-rate data around the moment something went wrong.

``ring`` (every reading of the window topics for the last INCIDENT_BEFORE_S, bounded
in bytes), ``triggers`` (what opens an incident: a diagnostics status, a /rosout
record, a topic condition, a mark by hand; pure), ``recorder`` (the incident's state:
open, extended, rate-limited, closed) and ``parts`` (a closed incident as UDM
``incident`` events under the batch byte limit; pure). docs/udm.md, "incident".
"""
