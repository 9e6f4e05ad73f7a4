"""The dead-letters command over a real queue file."""

from __future__ import annotations

import re
from pathlib import Path

import orjson
import pytest

from phytrace_edge.cli import main
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import DeadLetter
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import MIB
from tests.queue_events import put_events


@pytest.fixture
def queue_path(tmp_path: Path) -> str:
    path = tmp_path / "queue.db"
    with QueueStore.open(path, limits=QueueLimits(max_bytes=64 * MIB)) as store:
        put_events(store, [{"event_id": f"e{i}", "seq": i} for i in range(3)])
        batch = store.claim_batch(3, MIB)
        store.ack(batch, [DeadLetter(batch.events[1].id, "rejected: 422", 422, "bad seq")])
    return str(path)


def test_list_export_requeue_purge(
    queue_path: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["dead-letters", "list", "--queue-path", queue_path]) == 0
    heading, row = capsys.readouterr().out.splitlines()
    assert heading == f"1 dead letter(s) in {queue_path}"
    # queue id, when it was dead-lettered, event id, reason, PhyCloud's answer
    assert re.fullmatch(
        r" +1  \d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z  e1  rejected: 422  bad seq", row
    )

    export = tmp_path / "dead.jsonl"
    assert main(["dead-letters", "export", "-o", str(export), "--queue-path", queue_path]) == 0
    said = capsys.readouterr()  # the count on stderr: stdout may be the file (-o -)
    assert (said.out, said.err) == ("", "exported 1 dead letter(s)\n")
    (line,) = export.read_bytes().splitlines()
    assert orjson.loads(line)["event"] == {"event_id": "e1", "seq": 1}

    assert main(["dead-letters", "purge", "--queue-path", queue_path]) == 2
    said = capsys.readouterr()
    assert (said.out, said.err) == (
        "",
        "phytrace-edge: error: purge needs ids, --older-than-days or --all\n",
    )

    assert main(["dead-letters", "requeue", "--queue-path", queue_path]) == 0
    assert capsys.readouterr().out == "requeued 1 dead letter(s) at the end of the queue\n"
    with QueueStore.open(queue_path, limits=QueueLimits(max_bytes=64 * MIB)) as store:
        batch = store.claim_batch(10, MIB)
        assert [orjson.loads(e.json)["seq"] for e in batch.events] == [1]
        store.ack(batch, [DeadLetter(batch.events[0].id, "rejected: 400", 400)])

    assert main(["dead-letters", "purge", "--all", "--queue-path", queue_path]) == 0
    assert capsys.readouterr().out == "purged 1 dead letter(s)\n"
