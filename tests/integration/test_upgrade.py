"""The upgrade path, kept honest: queues and a hand-carry file written by the code of
earlier releases (tests/data/upgrade, made by tools/make_upgrade_fixtures.py from the
release's own tree) are read and drained by today's code, every event once.

- ``0.1.0-first``: the first build that said 0.1.0 (queue schema 3, before frames);
- ``0.1.0-last``: the last build that said 0.1.0 (tag v0.1.0: queue schema 6) and the
  ``.phx`` file its ``export`` wrote."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from phytrace_edge.queue.storage.migrate import latest_version
from tests.processes import run_cli, status_json

FIXTURES = Path(__file__).parents[1] / "data" / "upgrade"


def fixture(name: str) -> dict:
    return json.loads((FIXTURES / f"{name}.json").read_text())


@pytest.mark.parametrize(("name", "schema"), [("0.1.0-first", 3), ("0.1.0-last", 6)])
def test_a_queue_an_earlier_release_wrote_drains_completely(tmp_path, stub, name, schema) -> None:
    written = fixture(name)
    assert written["queue_schema_version"] == schema < latest_version() + 1
    queue = tmp_path / "queue.db"
    shutil.copy(FIXTURES / f"{name}.db", queue)
    env = {"QUEUE_PATH": str(queue), "PHYCLOUD_ENDPOINT": stub.endpoint}
    _, status = status_json(**env)  # status reads it as it is, before any migration
    assert status["queue"]["depth"] == len(written["event_ids"]), status

    drained = run_cli("drain", "--timeout", "60", **env)
    assert drained.returncode == 0, drained.stderr
    assert sorted(stub.event_ids()) == sorted(written["event_ids"])  # each once
    assert stub.stats()["duplicates"] == 0
    _, status = status_json(**env)
    assert status["queue"]["depth"] == 0 and status["sent_total"] == len(written["event_ids"])
    assert status["dead_letters"] == 0 and status["drops"] == {}, status


def test_a_hand_carry_file_the_last_0_1_0_wrote_imports_and_inspects(tmp_path, stub) -> None:
    written = fixture("0.1.0-last")
    assert written["phx"]
    stick = FIXTURES / "0.1.0-last.phx"
    before = stick.read_bytes()
    checked = run_cli("inspect", str(stick))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "(phx (0.1.0))" in checked.stdout and "written by phytrace-edge 0.1.0" in checked.stdout
    assert f"events       {len(written['event_ids'])} " in checked.stdout

    env = {"QUEUE_PATH": str(tmp_path / "laptop" / "queue.db"), "PHYCLOUD_ENDPOINT": stub.endpoint}
    imported = run_cli("import", str(stick), **env)
    assert imported.returncode == 0, imported.stderr
    assert sorted(stub.event_ids()) == sorted(written["event_ids"])
    assert stick.read_bytes() == before  # import never changes a file
