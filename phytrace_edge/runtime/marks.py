"""Marks by hand: ``phytrace-edge mark --reason TEXT`` tells the running bridge that
something went wrong, through files beside the queue.

The command writes ``marks/<time>-<pid>.mark`` (JSON: the reason and the moment, on
the wall clock) into the queue's directory, atomically; the service looks there every
``POLL_S``, takes each mark as an incident's trigger at the moment it was made (a
poll's delay does not move the window), answers in ``<same name>.done`` and removes
the mark. The command waits for that answer and says what became of the mark. Files
work for every way the bridge runs (systemd, a container with the volume mounted,
``ros2 launch``) and need no port; a mark made while no bridge runs is answered by
nobody, and the command removes it and says so.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

POLL_S = 0.25
MARK_SUFFIX, DONE_SUFFIX = ".mark", ".done"
REASON_MAX_CHARS = 512
STALE_ANSWER_S = 60.0


@dataclass(frozen=True)
class MarkRequest:
    """One mark waiting for the service: its file, the reason, when it was made."""

    path: Path
    reason: str
    at_wall_s: float


def marks_dir(queue_path: Path) -> Path:
    """Where marks for the bridge of ``queue_path`` go."""
    return queue_path.parent / "marks"


def write_mark(folder: Path, reason: str, at_wall_s: float) -> Path:
    """Leave a mark for the service; its file."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{time.time_ns()}-{os.getpid()}{MARK_SUFFIX}"
    _write_json(path, {"reason": reason, "at": at_wall_s})
    return path


def pending_marks(folder: Path) -> list[MarkRequest]:
    """The marks waiting, oldest first; one that cannot be read is answered as such."""
    try:
        files = list(folder.iterdir())
    except FileNotFoundError:
        return []
    for stale in (p for p in files if p.suffix == DONE_SUFFIX):
        with contextlib.suppress(OSError):  # an answer nobody waited for any more
            if time.time() - stale.stat().st_mtime > STALE_ANSWER_S:
                stale.unlink()
    names = sorted(p for p in files if p.suffix == MARK_SUFFIX)
    requests = []
    for path in names:
        try:
            found = json.loads(path.read_text("utf-8"))
            requests.append(MarkRequest(path, str(found["reason"]), float(found["at"])))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            answer(MarkRequest(path, "", 0.0), {"outcome": "unreadable", "detail": str(exc)})
    return requests


def answer(request: MarkRequest, reply: dict[str, Any]) -> None:
    """The service's answer to a mark; the mark is gone once it is given (a mark its
    command took back meanwhile gets none)."""
    if request.path.exists():
        _write_json(request.path.with_suffix(DONE_SUFFIX), reply)
    request.path.unlink(missing_ok=True)


def wait_for_answer(mark: Path, within_s: float) -> dict[str, Any] | None:
    """The service's answer to ``mark`` (its file is removed), or None when no answer
    came within ``within_s``: then the mark is taken back (removed unanswered)."""
    done = mark.with_suffix(DONE_SUFFIX)
    deadline = time.monotonic() + within_s
    while not done.exists() and time.monotonic() < deadline:
        time.sleep(0.05)  # a command waiting on another process's file: polled
    if not done.exists():
        mark.unlink(missing_ok=True)
        if not done.exists():  # (or answered just as it was taken back)
            return None
    reply: dict[str, Any] = json.loads(done.read_text("utf-8"))
    done.unlink(missing_ok=True)
    return reply


def _write_json(path: Path, document: dict[str, Any]) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_text(json.dumps(document), "utf-8")
    temporary.replace(path)  # whole or absent to the reader; a mark need not outlive power
