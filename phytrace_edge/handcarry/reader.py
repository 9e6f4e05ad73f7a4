"""Reading a hand-carry file (``handcarry.py`` describes the format): each record
through the ``mcap`` library's stream reader, with the byte offset where it starts, so
the first bad one is named and the events before it are kept."""

from __future__ import annotations

import hashlib
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson
import zstandard
from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, DataEnd, Footer, Header, Message, Metadata, Statistics
from mcap.stream_reader import StreamReader

from phytrace_edge.handcarry.format import (
    EXPORT_RECORD,
    MANIFEST_RECORD,
    MCAP_MAGIC,
    PROFILE,
    DamagedExport,
    Manifest,
    NotAnExport,
)

RECORD_MAX_BYTES = 256 * 1024 * 1024  # a longer record is a damaged length field
# anything a damaged file can make the parser raise
_PARSE_ERRORS = (McapError, ValueError, struct.error, zstandard.ZstdError, RuntimeError)


@dataclass
class ExportReader:
    """Reads a hand-carry file: iterate ``events()``; the manifest, the CRCs and the
    summary are checked on the way (``DamagedExport`` at the first that fails), and
    ``checks`` names what held."""

    path: Path
    header: dict[str, str] = field(default_factory=dict)
    manifest: Manifest | None = None
    checks: list[str] = field(default_factory=list)

    def events(self) -> Iterator[dict[str, Any]]:
        """Each event in order; raises ``DamagedExport`` at the first bad record, after
        the good events before it."""
        walk = _Walk(str(self.path), self)
        for offset, record in _records(self.path):
            yield from walk.take(offset, record)
        walk.whole()


@dataclass
class _Walk:
    """The state of one pass over a file's records (``ExportReader.events``)."""

    path: str
    reader: ExportReader
    channels: dict[int, str] = field(default_factory=dict)
    digest: Any = field(default_factory=hashlib.sha256)
    count: int = 0
    data_end: bool = False
    footer: tuple[int, Footer] | None = None

    def damage(self, offset: int, reason: str) -> DamagedExport:
        return DamagedExport(self.path, f"byte {offset}", reason)

    def take(self, offset: int, record: Any) -> Iterator[dict[str, Any]]:
        if isinstance(record, Header):
            _check_profile(self.path, offset, record)
        elif isinstance(record, Channel) and not self.data_end:
            self.channels[record.id] = record.topic
        elif isinstance(record, Message) and not self.data_end:
            yield self.event(offset, record)
        elif isinstance(record, Metadata):
            self.metadata(offset, record)
        elif isinstance(record, DataEnd):
            self.data_end = True
            if self.reader.manifest is None:
                raise self.damage(offset, "the data ends without a manifest")
            self.reader.checks += ["chunk CRCs", "data section CRC"]
        elif isinstance(record, Statistics) and record.message_count != self.count:
            raise self.damage(
                offset,
                f"the summary counts {record.message_count} events, the file has {self.count}",
            )
        elif isinstance(record, Footer):
            self.footer = (offset, record)

    def event(self, offset: int, message: Message) -> dict[str, Any]:
        if self.reader.manifest is not None:
            raise self.damage(offset, "an event after the manifest")
        if message.channel_id not in self.channels:
            raise self.damage(offset, f"an event on an unknown channel {message.channel_id}")
        try:
            event = orjson.loads(message.data)
        except orjson.JSONDecodeError as exc:
            raise self.damage(offset, f"an event that is not JSON ({exc})") from None
        if not isinstance(event, dict) or not isinstance(event.get("event_id"), str):
            raise self.damage(offset, "not an event (no event_id)")
        self.digest.update(message.data + b"\n")
        self.count += 1
        return event

    def metadata(self, offset: int, record: Metadata) -> None:
        if record.name == EXPORT_RECORD:
            self.reader.header = dict(record.metadata)
        elif record.name == MANIFEST_RECORD:
            try:
                manifest = Manifest.from_metadata(record.metadata)
            except (KeyError, ValueError):
                raise self.damage(offset, "a manifest of the wrong shape") from None
            if manifest.events != self.count:
                raise self.damage(
                    offset,
                    f"the manifest counts {manifest.events} events, the file has {self.count}",
                )
            if manifest.sha256 != self.digest.hexdigest():
                raise self.damage(offset, "the checksum does not match the events")
            self.reader.manifest = manifest
            self.reader.checks.append(f"manifest: {self.count} events, sha256")

    def whole(self) -> None:
        """After the last record: the summary is there and its CRC holds."""
        if self.footer is None:  # the reader stops only at a footer: defensive
            raise self.damage(0, "no footer")
        offset, footer = self.footer
        if not footer.summary_start:
            raise self.damage(offset, "no summary (the file's index)")
        with Path(self.path).open("rb") as raw:
            raw.seek(footer.summary_start)
            # the CRC covers the summary and the footer up to its own CRC field
            covered = raw.read(offset + 1 + 8 + 8 + 8 - footer.summary_start)
        if footer.summary_crc and zlib.crc32(covered) != footer.summary_crc:
            raise self.damage(footer.summary_start, "the summary's CRC does not match")
        self.reader.checks.append("summary CRC")


def _records(path: Path) -> Iterator[tuple[int, Any]]:
    """Each record of the file with the byte offset where it (or its chunk) starts;
    ``DamagedExport`` at the first that cannot be read or whose CRC fails."""
    with path.open("rb") as raw:
        if raw.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise NotAnExport(str(path), "byte 0", "not an MCAP file")
        raw.seek(0)
        records = StreamReader(raw, validate_crcs=True, record_size_limit=RECORD_MAX_BYTES).records
        offset = len(MCAP_MAGIC)
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except _PARSE_ERRORS as exc:
                raise DamagedExport(str(path), f"byte {offset}", _reason(exc)) from None
            yield offset, record
            # records of a chunk come after the whole chunk was read: the position is
            # where the next top-level record starts
            offset = raw.tell()


def _reason(exc: Exception) -> str:
    if isinstance(exc, EndOfFile):
        return "the file ends inside this record (truncated)"
    return f"cannot be read ({type(exc).__name__}: {exc})"


def _check_profile(path: str, offset: int, header: Header) -> None:
    if header.profile != PROFILE:
        raise NotAnExport(
            path,
            f"byte {offset}",
            f"an MCAP file, but not a phytrace-edge export (profile {header.profile!r})",
        )


def open_export(path: Path) -> ExportReader:
    """A reader of ``path`` (MCAP) after checking its header; ``NotAnExport`` if it is
    not a hand-carry file, ``DamagedExport`` if not even the header can be read."""
    for offset, record in _records(path):
        if not isinstance(record, Header):  # the MCAP format puts it first
            raise NotAnExport(str(path), f"byte {offset}", "an MCAP file without a header")
        _check_profile(str(path), offset, record)
        return ExportReader(path)
    raise DamagedExport(str(path), "byte 8", "the file ends after its magic (truncated)")
