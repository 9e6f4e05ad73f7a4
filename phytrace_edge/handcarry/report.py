"""What a hand-carry file holds and whether it is whole, read without uploading
anything (``phytrace-edge inspect``)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from phytrace_edge.handcarry import reader as handcarry_reader
from phytrace_edge.handcarry.format import DamagedExport, Manifest
from phytrace_edge.handcarry.transfer import open_handcarry
from phytrace_edge.udm.event import parse_timestamp


@dataclass
class FileReport:
    """One file, read to its end or to its first damage."""

    path: str
    format: str  # "MCAP" or "phx (0.1.0)"
    header: dict[str, str]
    events: int = 0
    per_type: dict[str, int] = field(default_factory=dict)  # most first
    first_captured_at: str | None = None
    last_captured_at: str | None = None
    manifest: Manifest | None = None
    checks: list[str] = field(default_factory=list)
    damage: str | None = None  # where and why, when the file is not whole

    @property
    def whole(self) -> bool:
        return self.damage is None


def inspect_file(path: Path) -> FileReport:
    """Read ``path`` through: counts, captured range, checks; ``NotAnExport`` if it is
    not a hand-carry file."""
    reader = open_handcarry(path)
    mcap = isinstance(reader, handcarry_reader.ExportReader)
    report = FileReport(str(path), "MCAP" if mcap else "phx (0.1.0)", {})
    first = last = None
    per_type: Counter[str] = Counter()
    try:
        for event in reader.events():
            report.events += 1
            per_type[str(event.get("event_type", "?"))] += 1
            captured = _captured(event.get("captured_at"))
            if captured is not None:
                if first is None or captured[0] < first[0]:
                    first = captured
                if last is None or captured[0] > last[0]:
                    last = captured
    except DamagedExport as damage:
        report.damage = f"{damage.where}: {damage.reason}"
    report.per_type = dict(per_type.most_common())
    report.header = {key: str(value) for key, value in reader.header.items()}
    report.manifest, report.checks = reader.manifest, list(reader.checks)
    report.first_captured_at = first[1] if first else None
    report.last_captured_at = last[1] if last else None
    return report


def _captured(value: object) -> tuple[float, str] | None:
    if not isinstance(value, str):
        return None
    try:
        return parse_timestamp(value), value
    except ValueError:
        return None
