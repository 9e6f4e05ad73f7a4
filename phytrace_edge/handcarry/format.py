"""The hand-carry file: a robot's backlog on a USB stick, for sites without a network.

An MCAP file (https://mcap.dev), the container rosbag2 writes by default, so Foxglove,
PlotJuggler, the ``mcap`` CLI and the MCAP libraries of every language open it
(docs/operations.md, "Hand-carry"). Written and read with the ``mcap`` library:

- the header's profile is ``phytrace``; a ``phytrace.export`` metadata record comes
  first (robot, schema and bridge version, when it was written);
- one channel per event type (``telemetry.periodic``, ``log.record``, ...), message
  encoding ``json``, whose schema is the UDM JSON Schema of that type
  (``udm.schema.event_type_schema``, encoding ``jsonschema``);
- one message per event, oldest first, its data exactly the JSON that was queued; log
  time is the event's ``captured_at``, publish time when it was queued, sequence its
  queue id;
- zstd chunks with a CRC each, a CRC over the data section, and a summary (index);
- last, the ``phytrace.manifest`` metadata record: what the file holds (``Manifest``),
  with a sha256 over every message's data and a newline.

A file without its manifest or summary, with a bad CRC, or whose count or checksum
does not match is damaged: ``handcarry_reader`` yields the events before the first bad
record and then raises ``DamagedExport`` with that record's byte offset, so an import
keeps what can be kept. ``handcarry_phx`` reads the files of 0.1.0.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import BinaryIO

import orjson
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from phytrace_edge._version import __version__
from phytrace_edge.durable import sync_folder
from phytrace_edge.udm.event import format_timestamp, timestamp_ns
from phytrace_edge.udm.schema import SCHEMA_VERSION, event_type_schema

MCAP_MAGIC = b"\x89MCAP0\r\n"
PROFILE = "phytrace"
EXPORT_RECORD = "phytrace.export"
MANIFEST_RECORD = "phytrace.manifest"
CHUNK_BYTES = 4 * 1024 * 1024  # uncompressed, at most: export ends one per batch
SUMMARY_ROOM = 4096  # bytes of a summary besides its schemas and chunk indexes
CHUNK_INDEX_BYTES = 160  # a chunk index record with a few channels


class DamagedExport(Exception):
    """The file is not a whole hand-carry file; ``where`` names the first bad record
    (``byte N`` in an MCAP file, ``line N`` in a 0.1.0 file)."""

    def __init__(self, path: str, where: str, reason: str) -> None:
        super().__init__(f"{path}: {where}: {reason}")
        self.where, self.reason = where, reason


class NotAnExport(DamagedExport):
    """The file is not a phytrace-edge hand-carry file at all."""


@dataclass
class Manifest:
    """What the file holds, written last (so it exists only in a whole file)."""

    source_id: str
    events: int = 0
    first_id: int | None = None
    last_id: int | None = None
    first_captured_at: str | None = None
    last_captured_at: str | None = None
    schema_version: str = SCHEMA_VERSION
    sha256: str = ""
    bridge_version: str = __version__

    def as_metadata(self) -> dict[str, str]:
        """MCAP metadata holds strings: None as an empty one."""
        return {
            f.name: "" if (v := getattr(self, f.name)) is None else str(v) for f in fields(self)
        }

    @classmethod
    def from_metadata(cls, data: dict[str, str]) -> Manifest:
        """ValueError or KeyError when a field is missing or not a number."""

        def number(key: str) -> int | None:
            return int(data[key]) if data[key] else None

        return cls(
            source_id=data["source_id"],
            events=int(data["events"]),
            first_id=number("first_id"),
            last_id=number("last_id"),
            first_captured_at=data["first_captured_at"] or None,
            last_captured_at=data["last_captured_at"] or None,
            schema_version=data["schema_version"],
            sha256=data["sha256"],
            bridge_version=data.get("bridge_version", ""),
        )


class ExportWriter:
    """Writes one hand-carry file to ``path + ".part"``; ``finish`` adds the manifest
    and the summary, fsyncs, and renames it to ``path``, so a file under its final name
    is whole."""

    def __init__(self, path: Path, source_id: str, now_s: float) -> None:
        self.path, self.part = path, path.with_name(path.name + ".part")
        self._raw: BinaryIO = self.part.open("wb")  # closed by finish or abort
        self._mcap = Writer(
            self._raw,
            chunk_size=CHUNK_BYTES,
            compression=CompressionType.ZSTD,
            enable_data_crcs=True,
        )
        self._mcap.start(PROFILE, f"phytrace-edge/{__version__} {LIBRARY_IDENTIFIER}")
        self._mcap.add_metadata(
            EXPORT_RECORD,
            {
                "source_id": source_id,
                "schema_version": SCHEMA_VERSION,
                "created_at": format_timestamp(now_s),
                "bridge_version": __version__,
            },
        )
        self._channels: dict[str, int] = {}
        self._schema_bytes: dict[str, int] = {}
        self._chunks = 0
        self._digest = hashlib.sha256()
        self.manifest = Manifest(source_id)

    @property
    def compressed_bytes(self) -> int:
        """Bytes on disk so far (exact after ``flush_block``)."""
        return self._raw.tell()

    @property
    def bytes_to_finish(self) -> int:
        """At most what ``finish`` adds: the manifest and the summary, which repeats
        each schema, and room for the schemas of types not seen yet (in a chunk and
        in the summary)."""
        unseen = [size for name, size in _schema_sizes().items() if name not in self._schema_bytes]
        schemas = sum(self._schema_bytes.values()) + 2 * sum(unseen)
        return SUMMARY_ROOM + schemas + CHUNK_INDEX_BYTES * (self._chunks + 1)

    def write(self, queue_id: int, event_json: bytes, queued_at_s: float) -> None:
        """One event as it was queued (``queued_at_s`` in unix seconds)."""
        event_type, captured_at, captured_ns = _type_and_time(event_json)
        queued_ns = _ns(queued_at_s)
        captured_ns = queued_ns if captured_ns is None else max(0, captured_ns)
        self._mcap.add_message(
            self._channel(event_type), captured_ns, event_json, queued_ns, queue_id % 2**32
        )
        self._digest.update(event_json + b"\n")
        m = self.manifest
        m.events += 1
        m.first_id = queue_id if m.first_id is None else m.first_id
        m.last_id = queue_id
        m.first_captured_at = m.first_captured_at or captured_at
        m.last_captured_at = captured_at or m.last_captured_at

    def _channel(self, event_type: str) -> int:
        if event_type not in self._channels:
            schema = orjson.dumps(event_type_schema(event_type))
            schema_id = self._mcap.register_schema(
                f"phytrace.udm/{event_type}", "jsonschema", schema
            )
            self._channels[event_type] = self._mcap.register_channel(event_type, "json", schema_id)
            self._schema_bytes[event_type] = len(schema)
        return self._channels[event_type]

    def flush_block(self) -> None:
        """End the chunk in progress, so ``compressed_bytes`` is exact."""
        self._mcap.flush()  # type: ignore[no-untyped-call]  # mcap's Writer is untyped
        self._chunks += 1

    def finish(self) -> Manifest:
        self._mcap.flush()  # type: ignore[no-untyped-call]
        self.manifest.sha256 = self._digest.hexdigest()
        self._mcap.add_metadata(MANIFEST_RECORD, self.manifest.as_metadata())
        self._mcap.finish()  # type: ignore[no-untyped-call]
        self._raw.flush()
        os.fsync(self._raw.fileno())
        self._raw.close()
        self.part.replace(self.path)
        sync_folder(self.path.parent)
        return self.manifest

    def abort(self) -> None:
        """Close and remove the unfinished file."""
        self._raw.close()
        self.part.unlink(missing_ok=True)


@functools.cache
def _schema_sizes() -> dict[str, int]:
    types = ("telemetry.periodic", "telemetry.topic", "log.record", "bridge.health")
    return {name: len(orjson.dumps(event_type_schema(name))) for name in types}


def _type_and_time(event_json: bytes) -> tuple[str, str | None, int | None]:
    """The event's type (its channel), ``captured_at`` and it in nanoseconds (None
    when it is not a timestamp); the queue holds only JSON objects, so anything else is
    named rather than refused."""
    try:
        event = orjson.loads(event_json)
    except orjson.JSONDecodeError:
        return "unknown", None, None
    if not isinstance(event, dict):
        return "unknown", None, None
    event_type, captured_at = event.get("event_type"), event.get("captured_at")
    event_type = event_type if isinstance(event_type, str) else "unknown"
    if not isinstance(captured_at, str):
        return event_type, None, None
    try:
        return event_type, captured_at, timestamp_ns(captured_at)
    except ValueError:  # not a time
        return event_type, None, None


def _ns(unix_s: float) -> int:
    """Nanoseconds for an MCAP time (unsigned: a time before 1970 reads as 0)."""
    return max(0, round(unix_s * 1e9))
