"""Write the upgrade fixtures: a queue, and a hand-carry file where that release could
write one, made by the code of an earlier release, for tests/integration/test_upgrade.py.

    .venv/bin/python tools/make_upgrade_fixtures.py --commit 258ca37 --name 0.1.0-first
    .venv/bin/python tools/make_upgrade_fixtures.py --commit v0.1.0 --name 0.1.0-last

The release's tree is taken with ``git archive`` into a temporary folder and run there
(this checkout's packages serve as its libraries): its own ``QueueStore`` queues
``--events`` UDM 1.0.0 events (valid under every schema since) and closes the queue; its
own ``export`` command, if it has one, writes the events to a ``.phx`` file from a copy.
Into ``tests/data/upgrade``: ``NAME.db``, ``NAME.phx`` and ``NAME.json`` (the commit,
the queue's schema version and the event ids, which the test expects back).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "upgrade"

# runs inside the release's tree: only its QueueStore.open and put_many, which every
# release has had (from 0.3.0 it takes Built events, before them plain ones)
QUEUE_EVENTS = """
import json, sys
from phytrace_edge.queue.store import QueueStore
try:
    from phytrace_edge.udm.types import Built
except ImportError:
    Built = None
events = json.loads(sys.stdin.read())
with QueueStore.open(sys.argv[1]) as store:
    result = store.put_many(events if Built is None else [Built(e) for e in events])
assert result.accepted == len(events), result
"""


def udm_events(count: int, name: str) -> list[dict]:
    """``count`` UDM 1.0.0 telemetry events of one robot, a second apart, with ids
    that say which fixture they belong to."""
    tag = sum(name.encode()) % 0xFFFF
    return [
        {
            "event_id": f"0194{tag:04x}-0000-7000-8000-{i:012x}",
            "event_type": "telemetry.periodic",
            "schema_version": "1.0.0",
            "captured_at": f"2026-11-20T08:{i // 60:02d}:{i % 60:02d}.000Z",
            "source_id": "upgrade-amr-1",
            "source_type": "amr",
            "identity": {"source_id": "upgrade-amr-1", "source_type": "amr"},
            "power": {"battery": {"voltage_v": 24.0 + i / 100, "state_of_charge_pct": 80.0}},
            "location": {
                "heading_deg": 90.0,
                "local": {"coordinate_frame": "map", "x_m": i * 0.5, "y_m": 1.0},
            },
        }
        for i in range(count)
    ]


def release_tree(commit: str, folder: Path) -> None:
    archive = subprocess.run(
        ["git", "archive", "--format=tar", commit], cwd=ROOT, capture_output=True, check=True
    ).stdout
    archive_path = folder / "release.tar"
    archive_path.write_bytes(archive)
    with tarfile.open(archive_path) as tar:
        tar.extractall(folder / "tree", filter="data")


def run_release(
    tree: Path, args: list[str], env: dict[str, str] | None = None, stdin: bytes = b""
) -> None:
    """Run the release's Python code; its own output on failure."""
    done = subprocess.run(
        [sys.executable, *args],
        cwd=tree,
        env={**os.environ, "PYTHONPATH": str(tree), **(env or {})},
        input=stdin,
        capture_output=True,
    )
    if done.returncode:
        sys.exit(f"{args[:3]} failed in the release's tree:\n{done.stderr.decode()}")


def single_file(queue: Path) -> int:
    """Fold the WAL into the file (a fixture is one file); the schema version."""
    with sqlite3.connect(queue) as connection:
        connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        version = connection.execute("PRAGMA user_version").fetchone()[0]
    connection.close()
    for suffix in ("-wal", "-shm"):
        Path(f"{queue}{suffix}").unlink(missing_ok=True)
    return int(version)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--commit", required=True, help="the release's commit or tag")
    parser.add_argument("--name", required=True, help="fixture name, e.g. 0.1.0-last")
    parser.add_argument("--events", type=int, default=60)
    args = parser.parse_args()
    events = udm_events(args.events, args.name)
    sys.path.insert(0, str(ROOT))  # today's validator: the events must stay valid UDM
    from phytrace_edge.udm.schema import find_violation

    assert all(find_violation(event) is None for event in events), find_violation(events[0])
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="upgrade-fixture-") as folder:
        work = Path(folder)
        release_tree(args.commit, work)
        tree = work / "tree"
        queue = work / "queue.db"
        run_release(tree, ["-c", QUEUE_EVENTS, str(queue)], stdin=json.dumps(events).encode())
        version = single_file(queue)
        shutil.copy(queue, OUT / f"{args.name}.db")
        has_export = (tree / "phytrace_edge" / "cli" / "export.py").exists()
        if has_export:
            carried = work / "carried.db"
            shutil.copy(queue, carried)
            phx = OUT / f"{args.name}.phx"
            phx.unlink(missing_ok=True)
            env = {"QUEUE_PATH": str(carried), "SOURCE_ID": "upgrade-amr-1"}
            run_release(tree, ["-m", "phytrace_edge", "export", "--out", str(phx)], env)
    release = _version_of(args.commit)
    (OUT / f"{args.name}.json").write_text(
        json.dumps(
            {
                "commit": _full_commit(args.commit),
                "version": release,
                "queue_schema_version": version,
                "phx": has_export,
                "event_ids": [event["event_id"] for event in events],
            },
            indent=1,
        )
        + "\n"
    )
    written = ", .phx written" if has_export else ""
    print(
        f"{args.name}: {release} at {args.commit}, queue schema {version}, "
        f"{args.events} events{written}"
    )


def _full_commit(commit: str) -> str:
    return subprocess.run(
        ["git", "rev-parse", f"{commit}^{{commit}}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def _version_of(commit: str) -> str:
    for path in ("phytrace_edge/_version.py", "phytrace_edge/__init__.py"):
        shown = subprocess.run(
            ["git", "show", f"{commit}:{path}"], cwd=ROOT, capture_output=True, text=True
        )
        for line in shown.stdout.splitlines():
            if line.startswith("__version__"):
                return line.split("=")[1].strip().strip("\"'")
    return "?"


if __name__ == "__main__":
    main()
