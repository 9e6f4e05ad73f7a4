"""``phytrace-edge dead-letters``: events PhyCloud refused for good."""

from __future__ import annotations

import argparse
import sys

from phytrace_edge.cli.common import checked
from phytrace_edge.config import LoadedSettings
from phytrace_edge.config.parsers import int_between, non_negative_float, path_value
from phytrace_edge.errors import EXIT_OK, ConfigError
from phytrace_edge.udm.event import format_timestamp

ID = int_between(1, 2**63 - 1)
LIMIT = int_between(1, 10**6)
DAYS = non_negative_float(36500)

NAME = "dead-letters"
HELP = "list, export, requeue or purge events PhyCloud rejected"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["list", "export", "requeue", "purge"])
    parser.add_argument(
        "ids", nargs="*", type=checked(ID, "id"), help="dead letter ids (default: all)"
    )
    parser.add_argument(
        "--limit", type=checked(LIMIT, "limit"), default=100, help="list at most this many"
    )
    parser.add_argument(
        "--output",
        "-o",
        type=checked(path_value, "path"),
        default="-",
        help="export to this file (- = stdout)",
    )
    parser.add_argument(
        "--older-than-days", type=checked(DAYS, "days"), help="purge only those older"
    )
    parser.add_argument("--all", action="store_true", help="purge all")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Inspect, export, requeue or purge events PhyCloud rejected for good."""
    ids = args.ids or None
    if args.action == "purge" and ids is None and args.older_than_days is None and not args.all:
        raise ConfigError("purge needs ids, --older-than-days or --all")
    from phytrace_edge.runtime import wiring

    with wiring.open_queue(loaded.settings) as store:
        box = store.dead_letters
        if args.action == "list":
            letters = box.list(limit=args.limit)
            print(f"{box.count()} dead letter(s) in {store.path}")
            for letter in letters:
                print(
                    f"{letter.id:>6}  {format_timestamp(letter.dead_at)}  {letter.event_id}  "
                    f"{letter.reason}  {(letter.response or '')[:60]}"
                )
        elif args.action == "export":
            if args.output == "-":
                written = box.export(sys.stdout.buffer)
            else:
                try:
                    with open(args.output, "wb") as out:  # noqa: PTH123 - a binary stream
                        written = box.export(out)
                except OSError as exc:
                    message = f"--output {args.output}: cannot write ({exc.strerror})"
                    raise ConfigError(message) from None
            print(f"exported {written} dead letter(s)", file=sys.stderr)
        elif args.action == "requeue":
            moved = box.requeue(ids)
            print(f"requeued {moved} dead letter(s) at the end of the queue")
            if box.count():
                print(f"{box.count()} dead letter(s) remain (the queue is full, or not selected)")
        else:
            days = args.older_than_days
            before = None if days is None else store.now() - days * 86400
            print(f"purged {box.purge(ids, before=before)} dead letter(s)")
    return EXIT_OK
