"""What every UDM event starts with (its envelope), and how a header stamp is reported.

A stamp is classified as ``epoch`` (Unix time), ``sim`` (USE_SIM_TIME: seconds of the
/clock timeline), ``non_epoch`` (a sensor clock that does not count from 1970, e.g.
time since boot, or a stamp more than a day in the future) or ``none`` (a zero stamp).
"""

from __future__ import annotations

from phytrace_edge.udm.event import format_timestamp, new_event_id
from phytrace_edge.udm.schema import SCHEMA_VERSION
from phytrace_edge.udm.types import Envelope, Stamp, UdmIdentity

EPOCH_2000_S = 946_684_800.0
FUTURE_TOLERANCE_S = 86_400.0


def envelope(
    identity: UdmIdentity,
    event_type: str,
    captured_at_s: float,
    event_id: str | None = None,
) -> Envelope:
    """The fields every event has; a new time-ordered ``event_id`` unless given."""
    return Envelope(
        event_id=event_id or new_event_id(int(captured_at_s * 1000)),
        event_type=event_type,
        schema_version=SCHEMA_VERSION,
        captured_at=format_timestamp(captured_at_s),
        source_id=identity["source_id"],
        source_type=identity["source_type"],
        identity=identity.copy(),
    )


def classify_stamp(stamp_ns: int | None, now_wall_s: float, use_sim_time: bool) -> Stamp:
    """A header stamp as ``{"clock": ..., "stamp" | "stamp_s": ...}`` (see module doc)."""
    if stamp_ns is None:
        return Stamp(clock="none")
    seconds = stamp_ns / 1e9
    if use_sim_time:
        return Stamp(clock="sim", stamp_s=round(seconds, 6))
    if EPOCH_2000_S <= seconds <= now_wall_s + FUTURE_TOLERANCE_S:
        return Stamp(clock="epoch", stamp=format_timestamp(seconds))
    return Stamp(clock="non_epoch", stamp_s=round(seconds, 6))
