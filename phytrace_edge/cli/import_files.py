"""``phytrace-edge import FILE...``: hand-carry files to PhyCloud, through the sender
(batches, retries, idempotency keys): importing a file twice stores nothing twice."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from phytrace_edge.cli.common import add_timeout_flag, error
from phytrace_edge.cli.signals import stop_on_signals
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_OK, EXIT_UNHEALTHY, QueueError
from phytrace_edge.runtime import options

if TYPE_CHECKING:  # the store and sender load their libraries: run() imports them
    from phytrace_edge.queue.store import QueueStore
    from phytrace_edge.ship.sender import Sender

NAME = "import"
HELP = (
    "upload hand-carry files made by export to PhyCloud; exit 0 when every event of "
    "every file was delivered"
)
CHUNK_EVENTS = 20_000  # staged, then sent, at a time: the staging queue stays small


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE", help="files to upload")
    add_timeout_flag(parser)


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Each file in turn: read it into a staging queue, then send that queue empty."""
    from phytrace_edge.runtime import wiring

    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    state_dir = options.queue_path(loaded.settings).parent
    state_dir.mkdir(parents=True, exist_ok=True)
    complete = True
    with (
        tempfile.TemporaryDirectory(prefix="import-", dir=state_dir) as staging,
        wiring.staging(loaded.settings, os.environ, Path(staging) / "queue.db") as parts,
    ):
        stop_on_signals(parts.sender.stop)
        for file in args.files:
            complete = _import_one(Path(file), parts.store, parts.sender, deadline) and complete
            if parts.sender.stop.is_set():
                break
    return EXIT_OK if complete else EXIT_UNHEALTHY


def _import_one(path: Path, store: QueueStore, sender: Sender, deadline: float | None) -> bool:
    """Read ``path`` into ``store`` and send it all; False when anything is missing."""
    from tqdm import tqdm

    from phytrace_edge.handcarry.format import NotAnExport
    from phytrace_edge.handcarry.transfer import export_chunks

    if not path.is_file():
        error(f"{path}: no such file")
        return False
    sent_before, read, delivered, damage = sender.stats.events_sent, 0, True, None
    with tqdm(unit="ev", desc=f"importing {path.name}", file=sys.stderr, disable=None) as bar:
        for chunk, found in export_chunks(path, CHUNK_EVENTS):
            read, damage = read + len(chunk), found
            if chunk and store.put_many(chunk).dropped:
                raise QueueError(f"{store.path}: the staging queue is full (disk full?)")
            delivered = sender.drain(deadline=deadline, progress=bar.update)
            if not delivered:
                break
    sent = sender.stats.events_sent - sent_before
    if isinstance(damage, NotAnExport):
        error(str(damage))
        return False
    if damage is not None:
        error(f"{damage}; the {read} event(s) before it were {'sent' if delivered else 'read'}")
    if not delivered:
        why = sender.stats.last_error or "stopped"
        error(f"{path}: sent {sent} of {read} event(s) read ({why}); run import again")
        sender.stop.set()  # the next files would fail alike
        return False
    if damage is None:
        print(f"imported {path}: {sent} event(s) delivered")
    return damage is None
