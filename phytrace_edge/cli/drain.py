"""``phytrace-edge drain``: send the whole backlog now, with a progress bar."""

from __future__ import annotations

import argparse
import os
import sys
import time

from phytrace_edge.cli.common import add_timeout_flag
from phytrace_edge.cli.signals import stop_on_signals
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_OK, EXIT_UNHEALTHY
from phytrace_edge.units import format_bytes

NAME = "drain"
HELP = "send the whole backlog now, with a progress bar"


def configure(parser: argparse.ArgumentParser) -> None:
    add_timeout_flag(parser)


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Send the whole backlog now; exit 0 only when the queue is empty at the end."""
    from tqdm import tqdm

    from phytrace_edge.runtime import wiring

    started = time.monotonic()
    with wiring.shipping(loaded.settings, os.environ) as parts:
        store, sender = parts.store, parts.sender
        stop_on_signals(sender.stop)
        depth = store.counter("depth")
        with tqdm(total=depth, unit="ev", desc="draining", file=sys.stderr, disable=None) as bar:

            def progress(sent: int) -> None:
                bar.update(sent)
                bar.set_postfix(left=format_bytes(store.counter("stored_bytes")))

            deadline = None if args.timeout is None else started + args.timeout
            empty = sender.drain(deadline=deadline, progress=progress)
        left = store.counter("depth")
    elapsed = time.monotonic() - started
    if empty:
        print(f"drained {sender.stats.events_sent} event(s) in {elapsed:.1f} s; the queue is empty")
        return EXIT_OK
    why = sender.stats.last_error or ("timeout" if args.timeout else "stopped")
    print(f"sent {sender.stats.events_sent} event(s) in {elapsed:.1f} s; {left} left ({why})")
    return EXIT_UNHEALTHY
