"""The hand-carry file in MCAP: what a whole file holds (read back by the ``mcap``
library's own reader as well as ours), and how each kind of damage is found and named
by the byte offset of its first bad record, with the events before it kept."""

from __future__ import annotations

import calendar
import struct
import tempfile
import time
from pathlib import Path

import fastjsonschema
import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer

from phytrace_edge.handcarry.format import DamagedExport, ExportWriter, NotAnExport
from phytrace_edge.handcarry.reader import open_export
from phytrace_edge.handcarry.transfer import export_backlog, open_handcarry
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.schema import event_type_schema
from tests.handcarry_files import read_all
from tests.queue_events import put_events
from tests.udm_events import EVENT_TYPES, every_type

IDENTITY = {"source_id": "amr-1", "source_type": "amr"}
START_S = 1_795_300_000.0
PER_CHUNK = 100


def write_file(path: Path, count: int) -> list[bytes]:
    """A file of ``count`` events of every type, a chunk per 100 (as export writes a
    chunk per batch); the events' JSON."""
    # odd milliseconds: a stamp a float cannot hold to the nanosecond
    jsons = [orjson.dumps(e) for e in every_type(count, IDENTITY, START_S, step_s=0.137)]
    writer = ExportWriter(path, "amr-1", START_S + 3600)
    for i, event_json in enumerate(jsons):
        writer.write(100 + i, event_json, START_S + i * 0.2 + 0.5)
        if i % PER_CHUNK == PER_CHUNK - 1:
            writer.flush_block()
    manifest = writer.finish()
    assert (manifest.events, manifest.first_id, manifest.last_id) == (count, 100, 99 + count)
    return jsons


def exact_ns(stamp: str) -> int:
    """``2026-11-21T22:26:40.137Z`` in nanoseconds, in integers only."""
    seconds = calendar.timegm(time.strptime(stamp[:19], "%Y-%m-%dT%H:%M:%S"))
    return seconds * 10**9 + int(stamp[20:23]) * 10**6


def chunk_offsets(path: Path) -> list[int]:
    with path.open("rb") as raw:
        summary = make_reader(raw).get_summary()
    assert summary is not None
    return [index.chunk_start_offset for index in summary.chunk_indexes]


def footer_offset(data: bytes) -> int:
    return len(data) - 8 - (1 + 8 + 8 + 8 + 4)  # magic after it; the footer's fixed size


def test_a_whole_file_reads_back_in_our_reader_and_the_mcap_library(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    jsons = write_file(path, 250)
    assert not (tmp_path / "a.mcap.part").exists()
    reader = open_export(path)
    assert [orjson.dumps(event) for event in reader.events()] == jsons
    assert reader.header["source_id"] == "amr-1"
    assert reader.manifest is not None and reader.manifest.events == 250
    assert reader.checks == [
        "manifest: 250 events, sha256",
        "chunk CRCs",
        "data section CRC",
        "summary CRC",
    ]
    with path.open("rb") as raw:
        library = make_reader(raw)
        assert library.get_header().profile == "phytrace"
        messages = list(library.iter_messages(log_time_order=False))
        metadata = {record.name: record.metadata for record in library.iter_metadata()}
    assert [message.data for _, _, message in messages] == jsons
    assert {channel.topic for _, channel, _ in messages} == set(EVENT_TYPES)
    for i, (schema, channel, message) in enumerate(messages):
        event = orjson.loads(message.data)
        assert channel.topic == event["event_type"] and channel.message_encoding == "json"
        assert schema is not None and schema.encoding == "jsonschema"
        assert orjson.loads(schema.data) == event_type_schema(channel.topic)
        assert message.log_time == exact_ns(event["captured_at"])
        assert message.publish_time == round((START_S + i * 0.2 + 0.5) * 1e9)
        assert message.sequence == 100 + i
    assert metadata["phytrace.manifest"]["events"] == "250"
    assert metadata["phytrace.manifest"]["sha256"] == reader.manifest.sha256
    assert metadata["phytrace.export"]["source_id"] == "amr-1"


def test_each_channel_schema_accepts_its_type_and_refuses_the_others() -> None:
    events = every_type(4, IDENTITY, START_S)
    for event in events:
        validate = fastjsonschema.compile(event_type_schema(event["event_type"]))
        validate(event)
        for other in events:
            if other["event_type"] != event["event_type"]:
                with pytest.raises(fastjsonschema.JsonSchemaValueException):
                    validate(other)


def flip(data: bytes, at: int) -> bytes:
    return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :]


def no_summary(data: bytes, chunks: list[int]) -> bytes:
    """The footer says there is no summary (summary_start 0), the summary bytes gone."""
    at = footer_offset(data)
    summary_start = struct.unpack_from("<Q", data, at + 9)[0]
    footer = bytes([data[at]]) + struct.pack("<QQQI", 20, 0, 0, 0)
    return data[:summary_start] + footer + data[-8:]


@pytest.mark.parametrize(
    ("damage", "where", "reason", "kept"),
    [
        # a flipped byte in the third chunk's compressed events
        (lambda d, c: flip(d, c[2] + 200), lambda d, c: c[2], "cannot be read", 200),
        # the file cut in the middle of the fourth chunk
        (lambda d, c: d[: c[3] + 300], lambda d, c: c[3], "ends inside this record", 300),
        # cut where the summary starts: the data is whole, the index is missing
        (
            lambda d, c: d[: struct.unpack_from("<Q", d, footer_offset(d) + 9)[0]],
            lambda d, c: struct.unpack_from("<Q", d, footer_offset(d) + 9)[0],
            "ends inside this record",
            450,
        ),
        # a footer that says there is no summary
        (no_summary, lambda d, c: footer_offset(d), "no summary", 450),
        # a flipped byte in the summary
        (
            lambda d, c: flip(d, footer_offset(d) - 14),  # in the last summary offset
            lambda d, c: struct.unpack_from("<Q", d, footer_offset(d) + 9)[0],
            "summary's CRC",
            450,
        ),
    ],
)
def test_damage_is_found_at_its_first_bad_record(
    tmp_path: Path, damage, where, reason, kept
) -> None:
    path = tmp_path / "a.mcap"
    jsons = write_file(path, 450)
    data, chunks = path.read_bytes(), chunk_offsets(path)
    damaged = damage(data, chunks)
    path.write_bytes(damaged)
    read, found = read_all(path)
    assert found is not None and reason in found.reason, found
    assert found.where == f"byte {where(data if reason != 'no summary' else damaged, chunks)}"
    assert [orjson.dumps(event) for event in read] == jsons[:kept]  # what came before is kept


def test_a_manifest_that_does_not_match_the_events_is_damage(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    write_file(path, 120)
    reader = open_export(path)
    list(reader.events())
    assert reader.manifest is not None
    data = path.read_bytes()
    digest = reader.manifest.sha256.encode()
    changed = data.replace(digest, digest[:-1] + (b"0" if digest[-1:] != b"0" else b"1"))
    path.write_bytes(changed)
    read, found = read_all(path)
    assert found is not None and "checksum does not match" in found.reason
    assert len(read) == 120  # every event came before the manifest


def test_files_that_are_not_exports_are_named(tmp_path: Path) -> None:
    ros = tmp_path / "ros.mcap"
    with ros.open("wb") as raw:
        writer = Writer(raw)
        writer.start("ros2", "someone else")
        writer.finish()
    with pytest.raises(NotAnExport, match="profile 'ros2'"):
        open_handcarry(ros)
    text = tmp_path / "notes.txt"
    text.write_text("just text\n")
    with pytest.raises(NotAnExport, match=r"neither MCAP nor \.phx"):
        open_handcarry(text)
    magic_only = tmp_path / "cut.mcap"
    magic_only.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(DamagedExport, match="truncated"):
        open_handcarry(magic_only)


# JSON values orjson writes and reads back unchanged: 64-bit integers, finite floats
json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=12,
)
events = st.builds(
    lambda n, event_type, captured, extra: {
        **extra,
        "event_id": f"0194aaaa-0000-7000-8000-{n:012x}",
        "event_type": event_type,
        "captured_at": captured,
    },
    st.integers(0, 2**40),
    st.sampled_from([*EVENT_TYPES, "some.future.type"]),
    st.sampled_from(["2026-11-20T08:00:00.000Z", "1970-01-01T00:00:00.000Z", "not a time"]),
    st.dictionaries(st.text(), json_values, max_size=5),
)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(events, min_size=1, max_size=40))
def test_any_events_survive_export_and_import_byte_for_byte(batch: list[dict]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        robot, laptop = Path(folder) / "robot.db", Path(folder) / "laptop.db"
        with QueueStore.open(robot) as store:
            assert put_events(store, batch).accepted == len(batch)
            manifest = export_backlog(store, Path(folder) / "x.mcap", "amr-1", 2**40)
        assert manifest is not None and manifest.events == len(batch)
        carried = list(open_handcarry(Path(folder) / "x.mcap").events())
        assert [orjson.dumps(event) for event in carried] == [orjson.dumps(e) for e in batch]
        with QueueStore.open(laptop) as store:
            put_events(store, carried)
            claimed = store.claim_batch(1000, 2**30, important_first=False)
        assert claimed is not None
        assert [event.json for event in claimed.events] == [orjson.dumps(e) for e in batch]
