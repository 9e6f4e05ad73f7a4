"""An independent reader: the MCAP project's TypeScript libraries (``@mcap/core``,
``@mcap/nodejs``) read every file ``export`` writes, in Node, and Ajv checks every
message against its channel's schema (mcap_reader/read.mjs). This shows the files are
MCAP as others read it, not only files our own reader accepts.

``python3 tools/test.py`` installs the npm packages (mcap_reader/package-lock.json);
without npm the test skips and says why, in CI it fails instead."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections import Counter
from pathlib import Path
from typing import NoReturn

import pytest

from phytrace_edge.handcarry.transfer import open_handcarry
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.schema import event_type_schema
from tests.processes import run_cli
from tests.queue_events import put_events
from tests.udm_events import EVENT_TYPES, every_type

READER = Path(__file__).with_name("mcap_reader")


def unavailable(why: str) -> NoReturn:
    """Skips the test, saying why; in CI the independent reader must run, never skip."""
    if os.environ.get("CI"):
        pytest.fail(why)
    pytest.skip(why)


def node_reader() -> list[str]:
    """The command that runs the reader; skips (fails in CI) when it cannot run."""
    node = shutil.which("node")
    if node is None:
        unavailable("node is not installed")
    if not (READER / "node_modules" / "@mcap" / "core").is_dir():
        unavailable(f"the npm packages are not installed in {READER} (python3 tools/test.py does)")
    return [node, str(READER / "read.mjs")]


def test_every_exported_file_reads_in_the_mcap_typescript_libraries(tmp_path: Path) -> None:
    command = node_reader()
    queue = tmp_path / "robot.db"
    identity = {"source_id": "mine-amr-3", "source_type": "amr"}
    events = every_type(4000, identity, 1_795_300_000.0, step_s=0.137)  # odd milliseconds
    with QueueStore.open(queue) as store:
        put_events(store, events)
    settings = {"QUEUE_PATH": str(queue), "SOURCE_ID": "mine-amr-3"}
    files = []
    for n in range(1, 10):
        files.append(tmp_path / f"day1-{n}.mcap")
        result = run_cli("export", "--out", str(files[-1]), "--max-bytes", "96KiB", **settings)
        if result.returncode == 0:
            break
        assert result.returncode == 1, result.stderr
    else:
        pytest.fail(f"the export did not finish in {len(files)} files of 96 KiB")
    assert len(files) >= 2, "the export fit one file: --max-bytes did not split it"

    done = subprocess.run(
        [*command, *map(str, files)], capture_output=True, text=True, timeout=120, cwd=READER
    )
    assert done.returncode == 0, done.stdout + done.stderr
    documents = [json.loads(line) for line in done.stdout.splitlines()]
    assert [document["file"] for document in documents] == list(map(str, files))
    total = 0
    for path, document in zip(files, documents, strict=True):
        ours = open_handcarry(path)
        read_back = list(ours.events())
        ids = [event["event_id"] for event in read_back]
        manifest = ours.manifest
        assert manifest is not None
        assert document["profile"] == "phytrace"
        assert {c["topic"] for c in document["channels"]} == set(EVENT_TYPES)
        for channel in document["channels"]:
            assert channel["messageEncoding"] == "json"
            assert channel["schemaEncoding"] == "jsonschema"
            assert channel["schemaName"] == f"phytrace.udm/{channel['topic']}"
        assert document["messages"] == document["statisticsMessageCount"] == len(ids)
        assert document["perTopic"] == dict(Counter(event["event_type"] for event in read_back))
        assert document["invalidCount"] == 0, document["invalid"]
        assert document["logTimeMismatches"] == 0
        written = document["metadata"]["phytrace.manifest"]
        assert written["events"] == str(manifest.events)
        assert written["sha256"] == manifest.sha256
        assert written["first_id"] == str(manifest.first_id)
        assert document["metadata"]["phytrace.export"]["source_id"] == "mine-amr-3"
        total += len(ids)
    assert total == 4000


def test_the_reader_refuses_what_breaks_a_channel_schema(tmp_path: Path) -> None:
    """The reader's checks can fail: an event its channel's schema refuses is counted."""
    command = node_reader()
    from phytrace_edge.handcarry.format import ExportWriter

    path = tmp_path / "bad.mcap"
    good, bad = every_type(2, {"source_id": "amr-1", "source_type": "amr"}, 1_795_300_000.0)
    bad = {**bad, "event_type": "telemetry.periodic"}  # a topic event on the periodic channel
    assert event_type_schema("telemetry.periodic")["allOf"]
    writer = ExportWriter(path, "amr-1", 1_795_300_100.0)
    for i, event in enumerate((good, bad)):
        writer.write(i + 1, json.dumps(event).encode(), 1_795_300_000.0)
    writer.finish()
    done = subprocess.run([*command, str(path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    document = json.loads(done.stdout)
    assert document["messages"] == 2 and document["invalidCount"] == 1
    assert document["invalid"][0]["event_id"] == bad["event_id"]
