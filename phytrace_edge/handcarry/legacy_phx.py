"""Hand-carry files of 0.1.0 (``.phx``), read-only: files on sticks in the field stay
importable; ``export`` writes MCAP since 0.2.0 (``handcarry.py``).

One zstd stream of JSON lines (docs/operations.md, "Hand-carry"):

1. a header: ``{"phytrace_export": 1, "source_id", "schema_version", "created_at",
   "bridge_version"}``;
2. the events, oldest first, one per line, exactly as they were queued;
3. a manifest: ``{"manifest": {"source_id", "events", "first_id", "last_id",
   "first_captured_at", "last_captured_at", "schema_version", "sha256"}}``, where the
   ids are the queue's and ``sha256`` covers every event line with its newline.

A file without its manifest, or whose count or checksum does not match, is damaged:
``ExportReader.events`` yields the events before the first bad line and then reports where
the damage starts, so an import keeps what can be kept.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson
import zstandard

from phytrace_edge.handcarry.format import DamagedExport, Manifest, NotAnExport

ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
FORMAT_VERSION = 1
LINE_MAX_BYTES = 16 * 1024 * 1024


def _damage(path: Path, line: int, reason: str) -> DamagedExport:
    return DamagedExport(str(path), f"line {line}", reason)


@dataclass
class ExportReader:
    """Reads a 0.1.0 hand-carry file: ``header`` first, then iterate ``events()``; the
    manifest is checked at the end (``DamagedExport`` otherwise)."""

    path: Path
    header: dict[str, Any]
    manifest: Manifest | None = None
    checks: list[str] = field(default_factory=list)

    def events(self) -> Iterator[dict[str, Any]]:
        """Each event in order; raises ``DamagedExport`` at the first bad line, after
        the good ones before it."""
        digest, line_number = hashlib.sha256(), 1
        for line_number, line in _lines(self.path, start=2):
            document = _parse(self.path, line_number, line)
            if "manifest" in document:
                events = line_number - 2  # the lines between the header and here
                self.manifest = _check_manifest(self.path, line_number, document, events, digest)
                self.manifest.bridge_version = str(self.header.get("bridge_version", ""))
                self.checks += ["zstd frame checksums", f"manifest: {events} events, sha256"]
                return
            if not isinstance(document.get("event_id"), str):
                raise _damage(self.path, line_number, "not an event (no event_id)")
            digest.update(line)
            yield document
        raise _damage(self.path, line_number + 1, "the file ends before its manifest (truncated)")


def open_export(path: Path) -> ExportReader:
    """A reader of ``path`` after checking its header; ``NotAnExport`` if it is not a
    hand-carry file at all."""
    for number, line in _lines(path, start=1):
        try:
            header = _parse(path, number, line)
        except DamagedExport as damage:
            raise NotAnExport(str(path), damage.where, damage.reason) from None
        if header.get("phytrace_export") != FORMAT_VERSION:
            raise NotAnExport(str(path), f"line {number}", "not a phytrace-edge export (no header)")
        return ExportReader(path, header)
    raise NotAnExport(str(path), "line 1", "empty file")


def _lines(path: Path, start: int) -> Iterator[tuple[int, bytes]]:
    """The file's decompressed lines with their numbers, from line ``start``."""
    number = 0
    try:
        with path.open("rb") as raw:
            reader = zstandard.ZstdDecompressor().stream_reader(raw, read_across_frames=True)
            for number, line in enumerate(io.BufferedReader(reader), start=1):
                if len(line) > LINE_MAX_BYTES:
                    raise _damage(path, number, "a line longer than 16 MiB")
                if number >= start:
                    yield number, line
    except zstandard.ZstdError as exc:
        cls = NotAnExport if number == 0 else DamagedExport
        raise cls(str(path), f"line {number + 1}", f"not readable zstd ({exc})") from None


def _parse(path: Path, number: int, line: bytes) -> dict[str, Any]:
    if not line.endswith(b"\n"):
        raise _damage(path, number, "cut off (truncated)")
    try:
        document = orjson.loads(line)
    except orjson.JSONDecodeError as exc:
        raise _damage(path, number, f"not JSON ({exc})") from None
    if not isinstance(document, dict):
        raise _damage(path, number, "not a JSON object")
    return document


def _check_manifest(
    path: Path, number: int, document: dict[str, Any], count: int, digest: Any
) -> Manifest:
    try:
        manifest = Manifest(**document["manifest"])
    except TypeError:
        raise _damage(path, number, "a manifest of the wrong shape") from None
    if manifest.events != count:
        raise _damage(
            path, number, f"the manifest counts {manifest.events} events, the file has {count}"
        )
    if manifest.sha256 != digest.hexdigest():
        raise _damage(path, number, "the checksum does not match the events")
    return manifest
