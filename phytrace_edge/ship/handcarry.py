"""The hand-carry file: a robot's backlog on a USB stick, for sites without a network.

One zstd stream of JSON lines (docs/operations.md, "Hand-carry"):

1. a header: ``{"phytrace_export": 1, "source_id", "schema_version", "created_at",
   "bridge_version"}``;
2. the events, oldest first, one per line, exactly as they were queued;
3. a manifest: ``{"manifest": {"source_id", "events", "first_id", "last_id",
   "first_captured_at", "last_captured_at", "schema_version", "sha256"}}``, where the
   ids are the queue's and ``sha256`` covers every event line with its newline.

A file without its manifest, or whose count or checksum does not match, is damaged:
``read_export`` yields the events before the first bad line and then reports where
the damage starts, so an import keeps what can be kept.
"""

from __future__ import annotations

import hashlib
import io
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import orjson
import zstandard

from phytrace_edge._version import __version__
from phytrace_edge.durable import sync_folder
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.udm.schema import SCHEMA_VERSION

FORMAT_VERSION = 1
ZSTD_LEVEL = 3
LINE_MAX_BYTES = 16 * 1024 * 1024


class DamagedExport(Exception):
    """The file is not a whole hand-carry file: ``line`` is the first bad line."""

    def __init__(self, path: str, line: int, reason: str) -> None:
        super().__init__(f"{path}: line {line}: {reason}")
        self.line, self.reason = line, reason


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


class ExportWriter:
    """Writes one hand-carry file to ``path + ".part"``; ``finish`` adds the manifest,
    fsyncs, and renames it to ``path``, so a file under its final name is whole."""

    def __init__(self, path: Path, source_id: str, now_s: float) -> None:
        self.path, self.part = path, path.with_name(path.name + ".part")
        self._raw: BinaryIO = self.part.open("wb")  # closed by finish or abort
        self._stream = zstandard.ZstdCompressor(level=ZSTD_LEVEL).stream_writer(
            self._raw, closefd=False
        )
        self._digest = hashlib.sha256()
        self.manifest = Manifest(source_id)
        header = {
            "phytrace_export": FORMAT_VERSION,
            "source_id": source_id,
            "schema_version": SCHEMA_VERSION,
            "created_at": format_timestamp(now_s),
            "bridge_version": __version__,
        }
        self._stream.write(orjson.dumps(header) + b"\n")

    @property
    def compressed_bytes(self) -> int:
        """Bytes on disk so far (what the compressor has flushed)."""
        return self._raw.tell()

    def write(self, queue_id: int, event_json: bytes) -> None:
        line = event_json + b"\n"
        self._stream.write(line)
        self._digest.update(line)
        m = self.manifest
        captured_at = _captured_at(event_json)
        m.events += 1
        m.first_id = queue_id if m.first_id is None else m.first_id
        m.last_id = queue_id
        m.first_captured_at = m.first_captured_at or captured_at
        m.last_captured_at = captured_at or m.last_captured_at

    def flush_block(self) -> None:
        """Push what was written to the file, so ``compressed_bytes`` is exact."""
        self._stream.flush(zstandard.FLUSH_BLOCK)

    def finish(self) -> Manifest:
        self.manifest.sha256 = self._digest.hexdigest()
        self._stream.write(orjson.dumps({"manifest": vars(self.manifest)}) + b"\n")
        self._stream.flush(zstandard.FLUSH_FRAME)
        self._stream.close()
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


def _captured_at(event_json: bytes) -> str | None:
    try:
        value = orjson.loads(event_json).get("captured_at")
    except (orjson.JSONDecodeError, AttributeError):
        return None
    return value if isinstance(value, str) else None


@dataclass
class ExportReader:
    """Reads a hand-carry file: ``header`` first, then iterate ``events()``; the
    manifest is checked at the end (``DamagedExport`` otherwise)."""

    path: Path
    header: dict[str, Any]
    manifest: Manifest | None = None

    def events(self) -> Iterator[dict[str, Any]]:
        """Each event in order; raises ``DamagedExport`` at the first bad line, after
        the good ones before it."""
        digest, line_number = hashlib.sha256(), 1
        for line_number, line in _lines(self.path, start=2):
            document = _parse(self.path, line_number, line)
            if "manifest" in document:
                events = line_number - 2  # the lines between the header and here
                self.manifest = _check_manifest(self.path, line_number, document, events, digest)
                return
            if not isinstance(document.get("event_id"), str):
                raise DamagedExport(str(self.path), line_number, "not an event (no event_id)")
            digest.update(line)
            yield document
        raise DamagedExport(
            str(self.path), line_number + 1, "the file ends before its manifest (truncated)"
        )


def open_export(path: Path) -> ExportReader:
    """A reader of ``path`` after checking its header; ``DamagedExport`` if it is not
    a hand-carry file at all."""
    for number, line in _lines(path, start=1):
        header = _parse(path, number, line)
        if header.get("phytrace_export") != FORMAT_VERSION:
            raise DamagedExport(str(path), number, "not a phytrace-edge export (no header)")
        return ExportReader(path, header)
    raise DamagedExport(str(path), 1, "empty file")


def _lines(path: Path, start: int) -> Iterator[tuple[int, bytes]]:
    """The file's decompressed lines with their numbers, from line ``start``."""
    number = 0
    try:
        with path.open("rb") as raw:
            reader = zstandard.ZstdDecompressor().stream_reader(raw, read_across_frames=True)
            for number, line in enumerate(io.BufferedReader(reader), start=1):
                if len(line) > LINE_MAX_BYTES:
                    raise DamagedExport(str(path), number, "a line longer than 16 MiB")
                if number >= start:
                    yield number, line
    except zstandard.ZstdError as exc:
        raise DamagedExport(str(path), number + 1, f"not readable zstd ({exc})") from None


def _parse(path: Path, number: int, line: bytes) -> dict[str, Any]:
    if not line.endswith(b"\n"):
        raise DamagedExport(str(path), number, "cut off (truncated)")
    try:
        document = orjson.loads(line)
    except orjson.JSONDecodeError as exc:
        raise DamagedExport(str(path), number, f"not JSON ({exc})") from None
    if not isinstance(document, dict):
        raise DamagedExport(str(path), number, "not a JSON object")
    return document


def _check_manifest(
    path: Path, number: int, document: dict[str, Any], count: int, digest: Any
) -> Manifest:
    try:
        manifest = Manifest(**document["manifest"])
    except TypeError:
        raise DamagedExport(str(path), number, "a manifest of the wrong shape") from None
    if manifest.events != count:
        raise DamagedExport(
            str(path), number, f"the manifest counts {manifest.events} events, the file has {count}"
        )
    if manifest.sha256 != digest.hexdigest():
        raise DamagedExport(str(path), number, "the checksum does not match the events")
    return manifest
