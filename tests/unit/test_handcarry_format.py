"""The hand-carry file format: what a whole file is, and how each kind of damage is
found and named by its first bad line."""

from __future__ import annotations

from pathlib import Path

import orjson
import pytest
import zstandard

from phytrace_edge.ship.handcarry import DamagedExport, ExportWriter, open_export


def write_file(path: Path, count: int) -> list[dict]:
    events = [{"event_id": f"id-{i}", "captured_at": f"t{i}", "n": i} for i in range(count)]
    writer = ExportWriter(path, "amr-1", 1_795_300_000.0)
    for i, event in enumerate(events):
        writer.write(100 + i, orjson.dumps(event))
        if i % 100 == 99:
            writer.flush_block()  # as export does after each batch
    manifest = writer.finish()
    assert (manifest.events, manifest.first_id, manifest.last_id) == (count, 100, 99 + count)
    assert (manifest.first_captured_at, manifest.last_captured_at) == ("t0", f"t{count - 1}")
    return events


def lines_of(path: Path) -> list[bytes]:
    return zstandard.ZstdDecompressor().stream_reader(path.read_bytes()).read().splitlines(True)


def rewrite(path: Path, lines: list[bytes]) -> None:
    path.write_bytes(zstandard.ZstdCompressor().compress(b"".join(lines)))


def read_all(path: Path) -> tuple[list[dict], DamagedExport | None]:
    events: list[dict] = []
    try:
        for event in open_export(path).events():
            events.append(event)
    except DamagedExport as damage:
        return events, damage
    return events, None


def test_a_whole_file_reads_back_with_its_manifest(tmp_path: Path) -> None:
    path = tmp_path / "a.phx"
    events = write_file(path, 50)
    assert not (tmp_path / "a.phx.part").exists()
    reader = open_export(path)
    assert reader.header["source_id"] == "amr-1"
    assert list(reader.events()) == events
    assert reader.manifest is not None and reader.manifest.events == 50


@pytest.mark.parametrize(
    ("damage", "line", "reason", "kept"),
    [
        (lambda lines: lines[:-1], 52, "ends before its manifest", 50),
        (lambda lines: [*lines[:10], lines[10][:5]], 11, "cut off", 9),
        (lambda lines: [*lines[:20], b"[1, 2]\n", *lines[21:]], 21, "not a JSON object", 19),
        (lambda lines: [*lines[:20], b'{"n": 1}\n', *lines[21:]], 21, "not an event", 19),
        (lambda lines: [*lines[:30], *lines[31:]], 51, "counts 50 events, the file has 49", 49),
        (
            lambda lines: [*lines[:30], lines[30].replace(b'"n":29', b'"n":28'), *lines[31:]],
            52,
            "checksum",
            50,
        ),
    ],
)
def test_damage_is_found_at_its_first_bad_line(tmp_path: Path, damage, line, reason, kept) -> None:
    path = tmp_path / "a.phx"
    events = write_file(path, 50)
    rewrite(path, damage(lines_of(path)))
    read, found = read_all(path)
    assert found is not None and found.line == line and reason in found.reason
    assert len(read) == kept  # what came before the damage is kept
    assert read[:9] == events[:9]


def test_a_truncated_zstd_stream_and_foreign_files_are_named(tmp_path: Path) -> None:
    path = tmp_path / "a.phx"
    write_file(path, 2000)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    read, found = read_all(path)
    assert found is not None and 0 < len(read) < 2000
    other = tmp_path / "b.phx"
    other.write_bytes(zstandard.ZstdCompressor().compress(b'{"hello": 1}\n'))
    with pytest.raises(DamagedExport, match="not a phytrace-edge export"):
        open_export(other)
    plain = tmp_path / "c.txt"
    plain.write_text("just text\n")
    with pytest.raises(DamagedExport, match="not readable zstd"):
        open_export(plain)
