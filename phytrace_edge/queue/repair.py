"""Timestamps repaired after a step of the wall clock (docs/udm.md, "Time").

An event stamped on this machine's wall clock while the kernel did not call it
synchronized carries ``wall_clock: {"synchronized": false}`` (the builder adds it).
When the clock then steps, the queued events of this boot stamped before the step get
``captured_at`` moved by the step and ``wall_clock.corrected_by_s`` saying by how much.

Which events were stamped before the step is decided from the event itself, not from
when it was queued (the step is seen up to a heartbeat after it happened): an event
stamped at queue time t reads ``t + offset`` on the clock of its time. It is repaired
when ``captured_at - offset_before`` falls within its row's queue times up to the step,
and ``captured_at - offset_after`` does not fall within them from the last look before
the step on. An event neither or both explain keeps its mark, uncorrected: PhyCloud can
tell that its time is doubtful. Rows being sent are repaired too: a sender that claimed
them before the step gives them back before its next attempt and sends them again
(``QueueStore.stepped_since``); only a request already on the wire at the step goes out
as it was, marked. Rows of earlier boots were stamped on another boot's clock.
"""

from __future__ import annotations

import logging
import sqlite3
from typing import Any

import orjson

from phytrace_edge.queue.clock import QueueTime, Step
from phytrace_edge.queue.codecs import Codecs
from phytrace_edge.queue.database import Database, bump_counters
from phytrace_edge.queue.frames import split_frame
from phytrace_edge.udm.event import format_timestamp, parse_timestamp

log = logging.getLogger(__name__)

STAMP_LATENCY_S = 2.0  # from the builder's stamp to the put: a tick and a commit
CHUNK_ROWS = 256


def stamped_before(captured_s: float, queued: tuple[float, float], step: Step) -> bool:
    """Whether an event of a row queued between ``queued`` (first, last) was stamped
    on the clock before ``step`` (see the module doc). Pure."""
    first, last = queued[0] - STAMP_LATENCY_S, queued[1]
    before = captured_s - step.offset_before
    after = captured_s - step.offset_after
    explained_before = first <= before <= min(last, step.at) + STAMP_LATENCY_S
    explained_after = max(first, step.looked_at - STAMP_LATENCY_S) <= after <= last
    return explained_before and not explained_after


def repaired(event: dict[str, Any], queued: tuple[float, float], step: Step) -> bool:
    """Move a marked event's ``captured_at`` by the step if it was stamped before it;
    whether it was changed."""
    clock = event.get("wall_clock")
    if not isinstance(clock, dict) or clock.get("synchronized") is not False:
        return False
    captured = event.get("captured_at")
    if not isinstance(captured, str):
        return False
    try:
        captured_s = parse_timestamp(captured)
    except ValueError:
        return False
    if not stamped_before(captured_s, queued, step):
        return False
    event["captured_at"] = format_timestamp(captured_s + step.seconds)
    clock["corrected_by_s"] = round(clock.get("corrected_by_s", 0.0) + step.seconds, 3)
    return True


def repair_queued(cursor: sqlite3.Cursor, codecs: Codecs, step: Step, boot_start: float) -> int:
    """Repair the rows of this boot queued up to the step, leased ones included (a
    sender retrying them sends them again, ``stepped_since``); events changed. Reads
    the rows by id, a chunk at a time: a step comes rarely, soon after a boot."""
    changed_events = size_change = 0
    last_id = 0
    while rows := cursor.execute(
        "SELECT id, count, queued_at, coalesce(newest_at, queued_at), codec, dict_id, body "
        "FROM events WHERE id > ? AND queued_at BETWEEN ? AND ? ORDER BY id LIMIT ?",
        (last_id, boot_start, step.at, CHUNK_ROWS),
    ).fetchall():
        last_id = rows[-1][0]
        for row_id, count, first, last, codec, dict_id, body in rows:
            jsons = split_frame(codecs.decode(codec, dict_id, body), count)
            events = [orjson.loads(json) for json in jsons]
            fixed = [repaired(event, (first, last), step) for event in events]
            if not any(fixed):
                continue
            changed_events += sum(fixed)
            jsons = [orjson.dumps(event) for event in events]
            encoded = codecs.encode(b"\n".join(jsons))
            size_change += len(encoded.body) - len(body)
            cursor.execute(
                "UPDATE events SET codec = ?, dict_id = ?, json_size = ?, body = ? WHERE id = ?",
                (encoded.codec, encoded.dict_id, sum(map(len, jsons)), encoded.body, row_id),
            )
    if size_change:
        bump_counters(cursor, stored_bytes=size_change)
    return changed_events


def record_clocks(db: Database, queue_time: QueueTime, codecs: Codecs) -> float:
    """Record the clocks (``clock.record_moment``) and, after a step, repair what was
    stamped before it, in one transaction; the step's seconds (0.0 for none)."""

    def record(cursor: sqlite3.Cursor) -> tuple[Step | None, int]:
        step = queue_time.record(cursor)
        if step is None:
            return None, 0
        return step, repair_queued(cursor, codecs, step, boot_start=queue_time.base)

    step, fixed = db.write(record, durable=False)
    if step is None:
        return 0.0
    log.warning(
        "queue %s: the wall clock stepped by %+.1f s; %d queued event(s) stamped before "
        "it repaired",
        db.path,
        step.seconds,
        fixed,
    )
    return step.seconds
