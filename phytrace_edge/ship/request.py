"""One HTTP request for a batch: body, compression, headers. Pure functions.

The body is assembled from the events' JSON as stored in the queue, without decoding
and re-encoding them: ``{"events": [<json>, <json>, ...]}``.
"""

from __future__ import annotations

import gzip
import hashlib
from collections.abc import Sequence

import zstandard

from phytrace_edge import __version__
from phytrace_edge.queue import QueuedEvent

GZIP_LEVEL = 6
ZSTD_LEVEL = 3
USER_AGENT = f"phytrace-edge/{__version__}"
_zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL)


def events_body(events: Sequence[QueuedEvent]) -> bytes:
    """The JSON body ``{"events": [...]}`` of a batch."""
    return b'{"events":[' + b",".join(event.json for event in events) + b"]}"


def encode_body(body: bytes, encoding: str) -> bytes:
    """``body`` compressed for ``Content-Encoding: encoding`` (gzip, zstd or none)."""
    if encoding == "gzip":
        return gzip.compress(body, GZIP_LEVEL, mtime=0)
    if encoding == "zstd":
        return _zstd.compress(body)
    return body


def idempotency_key(events: Sequence[QueuedEvent]) -> str:
    """The same batch always gets the same key: sha256 over its event ids, in order."""
    digest = hashlib.sha256()
    for event in events:
        digest.update(event.event_id.encode())
        digest.update(b"\n")
    return digest.hexdigest()


def request_headers(events: Sequence[QueuedEvent], encoding: str) -> dict[str, str]:
    """Headers of a batch request, except Authorization (the transport adds that)."""
    headers = {
        "Content-Type": "application/json",
        "Idempotency-Key": idempotency_key(events),
        "User-Agent": USER_AGENT,
    }
    if encoding != "none":
        headers["Content-Encoding"] = encoding
    return headers
