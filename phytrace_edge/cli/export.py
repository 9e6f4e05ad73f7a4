"""``phytrace-edge export``: the backlog into a hand-carry file (no network needed)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from phytrace_edge.cli.common import checked, error
from phytrace_edge.config import LoadedSettings
from phytrace_edge.config.parsers import byte_size
from phytrace_edge.errors import (
    EXIT_NOT_RUNNING,
    EXIT_OK,
    EXIT_UNHEALTHY,
    ConfigError,
    QueueError,
)
from phytrace_edge.runtime import options
from phytrace_edge.units import format_bytes

NAME = "export"
HELP = (
    "write the oldest queued events to a hand-carry file and remove them from the queue "
    "once the file is verified; exit 0 when the queue is empty, 1 when events are left"
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="the file to write (new)")
    parser.add_argument(
        "--max-bytes",
        type=checked(byte_size(64 * 1024), "a size like 4GiB, at least 64 KiB"),
        help="write at most about this much (the rest stays queued for the next file)",
    )


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    from tqdm import tqdm

    from phytrace_edge.handcarry.transfer import export_backlog
    from phytrace_edge.runtime import wiring

    settings, out = loaded.settings, Path(args.out)
    if not Path(options.queue_path(settings)).exists():
        error(
            f"no queue at {options.queue_path(settings)}: the bridge never ran with this QUEUE_PATH"
        )
        return EXIT_NOT_RUNNING
    if out.exists() or out.with_name(out.name + ".part").exists():
        raise ConfigError(f"--out {out} (or {out.name}.part) exists already: give a new file name")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: no such directory {out.parent}")
    with wiring.open_queue(settings) as store:
        total = store.counter("depth")
        with tqdm(total=total, unit="ev", desc="exporting", file=sys.stderr, disable=None) as bar:
            try:
                manifest = export_backlog(
                    store, out, settings.source_id, args.max_bytes or 2**62, bar.update
                )
            except OSError as exc:
                raise QueueError(
                    f"cannot write {out}: {exc.strerror or exc}; nothing was removed from the queue"
                ) from None
        left = store.counter("depth")
    if manifest is None:
        print("the queue is empty: nothing to export")
        return EXIT_OK
    print(
        f"exported {manifest.events} event(s) to {out} ({format_bytes(out.stat().st_size)}, "
        f"verified), captured {manifest.first_captured_at} to {manifest.last_captured_at}, "
        f"queue ids {manifest.first_id}-{manifest.last_id}"
    )
    if left:
        print(f"{left} event(s) left in the queue: run export again with another file")
        return EXIT_UNHEALTHY
    print("the queue is empty")
    return EXIT_OK
