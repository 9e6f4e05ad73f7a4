"""Hand-carry: a robot without a network exports its backlog to MCAP files, another
machine imports them, and PhyCloud (the real stub) holds every event of every type
exactly once, also when a file is imported twice, when an export is SIGKILLed mid-file,
and when a file is damaged (real queue files, real subprocesses, real HTTP)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from phytrace_edge.handcarry.transfer import BATCH_EVENTS, open_handcarry
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.event import format_timestamp
from phytrace_edge.udm.schema import SCHEMA_VERSION
from tests.processes import python_env, run_cli, wait_for
from tests.queue_events import put_events
from tests.udm_events import EVENT_TYPES, every_type

IDENTITY = {"source_id": "mine-amr-3", "source_type": "amr"}
START_S = 1_795_300_000.0


def fill_robot_queue(path: Path, count: int) -> list[str]:
    """A robot's backlog of ``count`` valid UDM events of every type (a day in a mine);
    their ids."""
    events = every_type(count, IDENTITY, START_S)
    with QueueStore.open(path) as store:
        for start in range(0, count, 5000):
            put_events(store, events[start : start + 5000])
    return [event["event_id"] for event in events]


def robot(queue: Path) -> dict[str, str]:
    """The robot's settings: its endpoint is unreachable (nothing listens on port 9)."""
    return {
        "QUEUE_PATH": str(queue),
        "PHYCLOUD_ENDPOINT": "http://127.0.0.1:9/api/v1",
        "SOURCE_ID": IDENTITY["source_id"],
    }


def says_exported(result: subprocess.CompletedProcess[str], out: Path, first: int, last: int):
    """The lines ``export`` printed after its summary, which must say it wrote the events
    of queue ids ``first`` to ``last`` (those ``fill_robot_queue`` captured 0.2 s apart)
    to ``out``. The file's size is not checked: it is compressed."""
    summary, *rest = result.stdout.splitlines()
    captured = [format_timestamp(START_S + (n - 1) * 0.2) for n in (first, last)]
    expected = (
        rf"exported {last - first + 1} event\(s\) to {re.escape(str(out))} \([\d.]+ \w+, "
        rf"verified\), captured {captured[0]} to {captured[1]}, queue ids {first}-{last}"
    )
    assert re.fullmatch(expected, summary), summary
    return rest


def laptop(tmp_path: Path, stub) -> dict[str, str]:
    return {"QUEUE_PATH": str(tmp_path / "laptop" / "queue.db"), "PHYCLOUD_ENDPOINT": stub.endpoint}


def test_export_on_two_sticks_then_import_twice_delivers_each_event_once(tmp_path, stub) -> None:
    queue = tmp_path / "robot.db"
    ids = fill_robot_queue(queue, 3000)
    first = run_cli(
        "export", "--out", str(tmp_path / "stick1.mcap"), "--max-bytes", "64KiB", **robot(queue)
    )
    assert first.returncode == 1, first.stderr  # events are left for the next stick
    second = run_cli("export", "--out", str(tmp_path / "stick2.mcap"), **robot(queue))
    assert second.returncode == 0, second.stderr
    sticks = [tmp_path / "stick1.mcap", tmp_path / "stick2.mcap"]
    assert sticks[0].stat().st_size <= 64 * 1024
    manifests = []
    for stick in sticks:
        reader = open_handcarry(stick)
        list(reader.events())
        manifests.append(reader.manifest)
    assert manifests[0].source_id == "mine-amr-3"
    assert manifests[0].schema_version == SCHEMA_VERSION
    assert manifests[0].last_id < manifests[1].first_id  # oldest first, no overlap
    assert sum(m.events for m in manifests) == 3000
    on_first = manifests[0].events
    assert says_exported(first, sticks[0], 1, on_first) == [
        f"{3000 - on_first} event(s) left in the queue: run export again with another file"
    ]
    assert says_exported(second, sticks[1], on_first + 1, 3000) == ["the queue is empty"]
    after = json.loads(run_cli("status", "--json", **robot(queue)).stdout)
    assert (after["exported_total"], after["queue"]["depth"]) == (3000, 0)

    imported = run_cli("import", *map(str, sticks), **laptop(tmp_path, stub))
    assert imported.returncode == 0, imported.stderr
    again = run_cli("import", str(sticks[0]), **laptop(tmp_path, stub))
    assert again.returncode == 0, again.stderr
    received = stub.event_ids()
    assert sorted(received) == sorted(ids)  # each event once
    assert stub.stats()["duplicates"] == manifests[0].events  # the second import, deduplicated


def test_an_export_killed_mid_file_loses_nothing_and_sends_nothing_twice(tmp_path, stub) -> None:
    queue = tmp_path / "robot.db"
    ids = fill_robot_queue(queue, 30_000)
    out = tmp_path / "stick.mcap"
    part = tmp_path / "stick.mcap.part"
    export = subprocess.Popen(
        [sys.executable, "-m", "phytrace_edge", "export", "--out", str(out)],
        env=python_env(**robot(queue)),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(
            # a whole chunk or more (one per batch, ~120 KiB), so the part holds events
            lambda: part.exists() and part.stat().st_size > 256 * 1024,
            60,
            "the export to write",
            every=0.005,
        )
    finally:
        os.kill(export.pid, signal.SIGKILL)
        export.wait(timeout=10)
    assert part.exists() and not out.exists(), "the export finished before it could be killed"

    # the operator imports the half-written file anyway: what it holds arrives once
    half = run_cli("import", str(part), **laptop(tmp_path, stub))
    assert half.returncode == 1 and "truncated" in half.stderr, half.stderr
    assert 0 < len(stub.event_ids()) < 30_000

    # and exports again: the killed export's claims come back, nothing was deleted
    again = run_cli("export", "--out", str(tmp_path / "stick-again.mcap"), **robot(queue))
    assert again.returncode == 0, again.stderr
    assert says_exported(again, tmp_path / "stick-again.mcap", 1, 30_000) == ["the queue is empty"]
    imported = run_cli(
        "import", str(tmp_path / "stick-again.mcap"), timeout=300, **laptop(tmp_path, stub)
    )
    assert imported.returncode == 0, imported.stderr
    assert sorted(stub.event_ids()) == sorted(ids)


def test_a_damaged_file_is_imported_up_to_its_first_bad_record(tmp_path, stub) -> None:
    queue = tmp_path / "robot.db"
    ids = fill_robot_queue(queue, BATCH_EVENTS + 1000)
    stick = tmp_path / "stick.mcap"
    assert run_cli("export", "--out", str(stick), **robot(queue)).returncode == 0
    with stick.open("rb") as raw:
        summary = make_reader(raw).get_summary()
    assert summary is not None and len(summary.chunk_indexes) == 2  # a chunk per batch
    second = summary.chunk_indexes[1].chunk_start_offset
    data = bytearray(stick.read_bytes())
    data[second + 400] ^= 0xFF  # a flipped bit in the second chunk's events
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))

    result = run_cli("import", str(damaged), **laptop(tmp_path, stub))
    assert result.returncode == 1
    assert f"{damaged}: byte {second}: cannot be read" in result.stderr
    assert f"the {BATCH_EVENTS} event(s) before it were sent" in result.stderr
    assert sorted(stub.event_ids()) == sorted(ids[:BATCH_EVENTS])
    assert damaged.read_bytes() == bytes(data)  # nothing is deleted or changed
    checked = run_cli("inspect", str(damaged))
    assert checked.returncode == 1 and f"byte {second}" in checked.stdout, checked.stdout

    # the whole file, from the robot's stick, completes it
    assert run_cli("import", str(stick), **laptop(tmp_path, stub)).returncode == 0
    assert sorted(stub.event_ids()) == sorted(ids)


def test_an_out_file_that_exists_or_has_no_folder_is_a_bad_argument(tmp_path: Path) -> None:
    """exit 2 and one line, as for any bad argument; the queue keeps every event."""
    queue = tmp_path / "robot" / "queue.db"
    queue.parent.mkdir()
    fill_robot_queue(queue, 3)
    taken = tmp_path / "stick.mcap"
    taken.write_bytes(b"someone else's file")
    for out, says in ((taken, "exists already"), (tmp_path / "no" / "f", "no such directory")):
        result = run_cli("export", "--out", str(out), **robot(queue))
        assert result.returncode == 2, result.stderr
        assert says in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert taken.read_bytes() == b"someone else's file"
    with QueueStore.open(queue) as store:
        assert store.counter("depth") == 3


def test_inspect_says_whole_damaged_or_not_an_export_by_its_exit_code(tmp_path: Path) -> None:
    queue = tmp_path / "robot.db"
    count = 10 * len(EVENT_TYPES)
    fill_robot_queue(queue, count)
    stick = tmp_path / "stick.mcap"
    assert run_cli("export", "--out", str(stick), **robot(queue)).returncode == 0
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(stick.read_bytes()[:-200])  # the summary's tail is gone
    notes = tmp_path / "notes.txt"
    notes.write_text("not an export\n")

    whole = run_cli("inspect", "--json", str(stick))
    assert whole.returncode == 0, whole.stderr
    report = json.loads(whole.stdout)
    assert report["whole"] and report["events"] == count and report["damage"] is None
    assert report["per_type"] == dict.fromkeys(EVENT_TYPES, 10)
    assert report["manifest"]["source_id"] == IDENTITY["source_id"]
    damaged = run_cli("inspect", str(stick), str(cut))
    assert damaged.returncode == 1
    whole, where, verdict = verdicts(damaged.stdout)
    assert whole == f"whole: an import delivers all {count} event(s)"
    cut_at = re.fullmatch(
        r"  damaged      byte (\d+): the file ends inside this record \(truncated\)", where
    )
    assert cut_at and 0 < int(cut_at[1]) < len(cut.read_bytes()), where
    assert verdict == f"damaged: an import delivers the {count} event(s) before the damage"
    foreign = run_cli("inspect", str(stick), str(notes))
    assert foreign.returncode == 2
    assert verdicts(foreign.stdout) == [f"whole: an import delivers all {count} event(s)"]
    assert foreign.stderr == (
        f"phytrace-edge: error: {notes}: byte 0: "
        "not a phytrace-edge export (neither MCAP nor .phx)\n"
    )


def verdicts(report: str) -> list[str]:
    """``inspect``'s lines on each file's state: its verdict, and where damage begins."""
    return [
        line
        for line in report.splitlines()
        if line.startswith(("whole: ", "damaged: ", "  damaged "))
    ]
