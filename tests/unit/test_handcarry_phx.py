"""Hand-carry files of 0.1.0 (``.phx``), which only import reads now: the file the last
0.1.0 wrote (tests/data/upgrade, tools/make_upgrade_fixtures.py) reads back whole, and
each kind of damage is found and named by its first bad line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import zstandard

from phytrace_edge.handcarry.format import NotAnExport
from phytrace_edge.handcarry.legacy_phx import open_export
from phytrace_edge.handcarry.transfer import open_handcarry
from tests.handcarry_files import read_all

FIXTURES = Path(__file__).parents[1] / "data" / "upgrade"
WRITTEN = FIXTURES / "0.1.0-last.phx"
IDS = json.loads((FIXTURES / "0.1.0-last.json").read_text())["event_ids"]
COUNT = len(IDS)


def lines_of(path: Path) -> list[bytes]:
    return zstandard.ZstdDecompressor().stream_reader(path.read_bytes()).read().splitlines(True)


def rewrite(path: Path, lines: list[bytes]) -> None:
    path.write_bytes(zstandard.ZstdCompressor().compress(b"".join(lines)))


def test_the_file_0_1_0_wrote_reads_back_with_its_manifest() -> None:
    reader = open_handcarry(WRITTEN)
    assert reader.header["source_id"] == "upgrade-amr-1"
    assert [event["event_id"] for event in reader.events()] == IDS
    assert reader.manifest is not None and reader.manifest.events == COUNT
    assert reader.manifest.bridge_version == "0.1.0"
    assert reader.checks[-1] == f"manifest: {COUNT} events, sha256"


@pytest.mark.parametrize(
    ("damage", "line", "reason", "kept"),
    [
        (lambda lines: lines[:-1], COUNT + 2, "ends before its manifest", COUNT),
        (lambda lines: [*lines[:10], lines[10][:5]], 11, "cut off", 9),
        (lambda lines: [*lines[:20], b"[1, 2]\n", *lines[21:]], 21, "not a JSON object", 19),
        (lambda lines: [*lines[:20], b'{"n": 1}\n', *lines[21:]], 21, "not an event", 19),
        (
            lambda lines: [*lines[:30], *lines[31:]],
            COUNT + 1,
            f"counts {COUNT} events, the file has {COUNT - 1}",
            COUNT - 1,
        ),
        (
            lambda lines: (
                [
                    *lines[:30],
                    lines[30].replace(b'"state_of_charge_pct":80.0', b'"state_of_charge_pct":8.0'),
                    *lines[31:],
                ]
            ),
            COUNT + 2,
            "checksum",
            COUNT,
        ),
    ],
)
def test_damage_is_found_at_its_first_bad_line(tmp_path: Path, damage, line, reason, kept) -> None:
    path = tmp_path / "a.phx"
    lines = lines_of(WRITTEN)
    changed = damage(lines)
    assert changed != lines
    rewrite(path, changed)
    read, found = read_all(path)
    assert found is not None and found.where == f"line {line}" and reason in found.reason
    assert len(read) == kept  # what came before the damage is kept
    assert [event["event_id"] for event in read[:9]] == IDS[:9]


def test_a_truncated_zstd_stream_and_foreign_files_are_named(tmp_path: Path) -> None:
    path = tmp_path / "a.phx"
    raw = WRITTEN.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    read, found = read_all(path)
    assert found is not None and len(read) < COUNT
    other = tmp_path / "b.phx"
    other.write_bytes(zstandard.ZstdCompressor().compress(b'{"hello": 1}\n'))
    with pytest.raises(NotAnExport, match="not a phytrace-edge export"):
        open_export(other)
