"""Event ids and timestamps of the UDM (stdlib only: ``status`` formats its times here)."""

from __future__ import annotations

import os
import time
from datetime import datetime, timedelta, timezone


def new_event_id(unix_ms: int | None = None, entropy: bytes | None = None) -> str:
    """A UUIDv7 (RFC 9562): unique, and sortable by creation time to the millisecond.

    Time-ordered ids keep PhyCloud's index inserts local and let an operator read the
    order of events from their ids. The stdlib has ``uuid.uuid7`` only from 3.14.
    ``entropy`` (10 bytes, e.g. a digest) replaces the random bits: the same input then
    gives the same id (an incident replayed from the same bag).
    """
    ms = time.time_ns() // 1_000_000 if unix_ms is None else unix_ms
    bits = os.urandom(10) if entropy is None else entropy[:10].ljust(10, b"\0")
    value = (ms & (2**48 - 1)) << 80 | int.from_bytes(bits, "big")
    value = value & ~(0xF << 76) | 0x7 << 76  # version 7
    value = value & ~(0x3 << 62) | 0x2 << 62  # RFC 4122 variant
    text = f"{value:032x}"
    return f"{text[:8]}-{text[8:12]}-{text[12:16]}-{text[16:20]}-{text[20:]}"


def is_event_type(json: bytes, event_type: str) -> bool:
    """Whether a queued event's JSON is of ``event_type``, without parsing it: the
    bridge writes ``event_id`` first and ``event_type`` second (``builder.envelope``;
    orjson keeps the order), so the type is within the first 128 bytes."""
    return b'"event_type":"' + event_type.encode() + b'"' in json[:128]


def parse_timestamp(text: str) -> float:
    """Unix seconds of an ISO-8601 timestamp (``format_timestamp``'s or with an offset);
    ValueError for anything else."""
    return _moment(text).timestamp()


def timestamp_ns(text: str) -> int:
    """Nanoseconds since 1970 of such a timestamp, exactly: a float of unix seconds
    holds about 16 digits, and 2026 in nanoseconds has 19 (off by up to 256 ns)."""
    return (_moment(text) - _EPOCH) // timedelta(microseconds=1) * 1000


def _moment(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00"))


_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)


def format_timestamp(unix_s: float) -> str:
    """UTC ISO-8601 with milliseconds and ``Z``: ``2025-01-15T14:23:01.042Z``."""
    ms = round(unix_s * 1000)
    return f"{time.strftime('%Y-%m-%dT%H:%M:%S', time.gmtime(ms // 1000))}.{ms % 1000:03d}Z"


def format_timestamp_us(unix_s: float) -> str:
    """UTC ISO-8601 with microseconds and ``Z``: ``2025-01-15T14:23:01.042315Z``, for
    the samples of an incident (a 500 Hz topic's messages are 2 ms apart)."""
    us = round(unix_s * 1_000_000)
    seconds = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(us // 1_000_000))
    return f"{seconds}.{us % 1_000_000:06d}Z"
