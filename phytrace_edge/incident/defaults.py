"""Defaults of the incident settings (docs/configuration.md, "Incident windows")."""

from __future__ import annotations

DEFAULT_INCIDENT_TOPICS = (
    "/odom",
    "/imu/data",
    "/cmd_vel",
    "/joint_states",
    "/battery_state",
    "/scan",
)
DEFAULT_INCIDENT_BEFORE_S = 30.0
DEFAULT_INCIDENT_AFTER_S = 10.0
DEFAULT_INCIDENT_BUFFER_MAX_BYTES = 16 * 1024 * 1024
DEFAULT_INCIDENT_DIAGNOSTICS_LEVEL = "error"  # ok < warn < error < stale; "off": never
DEFAULT_INCIDENT_ROSOUT_LEVEL = "error"  # error or fatal; "off": never
DEFAULT_INCIDENT_MAX_PER_HOUR = 12
DEFAULT_INCIDENT_MAX_S = 120.0  # triggers extend a window at most this far past its first
