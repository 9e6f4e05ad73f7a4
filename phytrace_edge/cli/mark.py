"""``phytrace-edge mark``: tell the running bridge something went wrong, now.

The bridge records an incident around this moment: its window topics at full rate
from INCIDENT_BEFORE_S before to INCIDENT_AFTER_S after (docs/operations.md, "After an
incident: where its data is"). The mark reaches the bridge through a file beside its
queue (``runtime/marks.py``); the command waits for the bridge's answer.
"""

from __future__ import annotations

import argparse
import time

from phytrace_edge.cli.common import checked, error
from phytrace_edge.config import LoadedSettings
from phytrace_edge.config.parsers import positive_float
from phytrace_edge.errors import EXIT_NOT_RUNNING, EXIT_OK, EXIT_UNHEALTHY
from phytrace_edge.runtime import marks, options

NAME = "mark"
HELP = (
    "mark an incident now: the running bridge records its window topics at full rate "
    "around this moment; exit 0 when it did, 1 when it did not (rate-limited, off), 3 "
    "when no bridge runs with this QUEUE_PATH"
)
ANSWERS = {
    "opened": "incident {incident_id} recorded around this mark: it is sent once its window ends",
    "extended": "incident {incident_id} was already being recorded: its window now ends later",
}
REFUSALS = {
    "rate_limited": "the bridge took the mark but recorded nothing: INCIDENT_MAX_PER_HOUR "
    "incidents were recorded in the last hour (status counts it as rate-limited)",
    "off": "incident recording is off on this bridge (INCIDENT_RECORDING=false)",
}


def reason(text: str) -> str:
    """The reason: one line of text, at most REASON_MAX_CHARS characters."""
    value = text.strip()
    if not value or len(value) > marks.REASON_MAX_CHARS or not value.isprintable():
        raise ValueError(f"one line of text, 1 to {marks.REASON_MAX_CHARS} characters")
    return value


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--reason", required=True, type=checked(reason, "a reason"), help="what happened"
    )
    parser.add_argument(
        "--wait",
        type=checked(positive_float(300), "seconds"),
        default=10.0,
        help="seconds to wait for the bridge's answer (default 10)",
    )


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    folder = marks.marks_dir(options.queue_path(loaded.settings))
    if not folder.parent.is_dir():
        error(f"no bridge has run here: {folder.parent} does not exist (QUEUE_PATH)")
        return EXIT_NOT_RUNNING
    mark = marks.write_mark(folder, args.reason, time.time())
    reply = marks.wait_for_answer(mark, args.wait)
    if reply is None:
        error(
            f"no running bridge took the mark within {args.wait:g} s (is one running with "
            "this QUEUE_PATH? phytrace-edge status); nothing was recorded"
        )
        return EXIT_NOT_RUNNING
    outcome = str(reply.get("outcome"))
    if outcome in ANSWERS:
        print(ANSWERS[outcome].format(incident_id=reply.get("incident_id")))
        return EXIT_OK
    error(REFUSALS.get(outcome) or f"the bridge did not take the mark: {reply.get('detail')}")
    return EXIT_UNHEALTHY
