"""Timestamps repaired after a step of the wall clock (docs/udm.md, "Time").

An event stamped on this machine's wall clock while the kernel did not call it
synchronized carries ``wall_clock: {"synchronized": false}`` (the builder adds it).
When the clock then steps, the queued events of this boot stamped before the step get
``captured_at`` moved by the step and ``wall_clock.corrected_by_s`` saying by how much.

Which events were stamped before the step is decided from the event itself, not from
when it was queued (the step is seen up to a heartbeat after it happened, and an event
may wait in the writer's memory for any time before it is queued): an event stamped at
queue time t reads ``t + offset`` on the clock of its time. It is repaired when
``captured_at - offset_before`` falls between this boot's start and the step, and
``captured_at - offset_after`` does not fall between the last look before the step and
the last time its row was queued. An event neither or both explain keeps its mark,
uncorrected: PhyCloud can tell that its time is doubtful. Rows being sent are repaired
too: a sender that claimed them before the step gives them back before its next attempt
and sends them again (``QueueStore.stepped_since``); only a request already on the wire
at the step goes out as it was, marked. Rows of earlier boots were stamped on another
boot's clock.

Which rows are looked at is decided by the order of transactions, not by times: the
rows in the queue when the step is recorded are the repair's (below); a row put after
that, in a transaction of its own, is looked at in that transaction against every step
this process has recorded (``ClockKeeper.repair_put``). So an event stamped before a
step and still in flight when the repair started (the writer batches in memory) is
repaired as it reaches the queue, and no sender ever sees it unrepaired.

A day's backlog takes seconds to rewrite (10 s for 432,000 events here), so the repair
goes a chunk of rows per transaction, half a second per look at the clocks, and the
rows still to be repaired are held under a lease of the repairing process meanwhile:
no sender claims them, no cap or TTL drops them. The repair under way is kept in
``meta``; a process that opens the queue after a crash goes on with it.
"""

from __future__ import annotations

import logging
import sqlite3
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import orjson

from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.encoding.frames import split_frame
from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.storage.database import Database, bump_counters
from phytrace_edge.queue.timekeeping.clock import Step, SystemClocks, open_queue_time
from phytrace_edge.udm.event import format_timestamp, parse_timestamp

log = logging.getLogger(__name__)

STAMP_MARGIN_S = 2.0  # around the step's looks and the boot's start: millisecond stamps
READ_MARGIN_S = 0.5  # stamped before queued, give or take a look's two clock reads
CHUNK_ROWS = 16  # a transaction: up to 16 frames of 100 events, some 40 ms
REPAIR_BUDGET_S = 0.5  # of repairing per look at the clocks (the heartbeat's, every 2 s)
REPAIR_KEY = "clock_repair"


def stamped_before(captured_s: float, stamped: tuple[float, float], step: Step) -> bool:
    """Whether an event stamped within ``stamped`` (queue times: this boot's start,
    and the last time its row was queued) was stamped on the clock before ``step``
    (see the module doc). How long the event waited before it was queued does not
    matter: an event stamped after the step always falls within the after clock's
    window, so it is never taken for one stamped before. Pure."""
    since, last = stamped
    before = captured_s - step.offset_before
    after = captured_s - step.offset_after
    explained_before = since - STAMP_MARGIN_S <= before <= min(last, step.at) + STAMP_MARGIN_S
    explained_after = step.looked_at - STAMP_MARGIN_S <= after <= last + READ_MARGIN_S
    return explained_before and not explained_after


def repaired(event: dict[str, Any], stamped: tuple[float, float], steps: Sequence[Step]) -> bool:
    """Move a marked event's ``captured_at`` by each of ``steps`` (in the order they
    were seen) it was stamped before; whether it was changed."""
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
    changed = False
    for step in steps:  # once moved by one, the stamp reads as taken on the next clock
        if stamped_before(captured_s, stamped, step):
            captured_s += step.seconds
            clock["corrected_by_s"] = round(clock.get("corrected_by_s", 0.0) + step.seconds, 3)
            changed = True
    if changed:
        event["captured_at"] = format_timestamp(captured_s)
    return changed


Ids = tuple[int, int]  # a range of row ids, both ends included


class Repair(NamedTuple):
    """A repair under way: the rows within ``ranges`` queued between ``boot_start``
    and the step are still to be looked at. Kept in ``meta`` (a restart goes on with
    it), the ranges leased to the repairer, so that no one sends or drops those rows
    before they are repaired."""

    step: Step
    boot_start: float
    ranges: list[Ids]
    repaired: int = 0  # events changed so far


class ClockKeeper:
    """Queue time for one store (``clock``), and its looks at the clocks: it records
    them, and after a step repairs what was stamped before it, the rows still to
    repair leased to ``<owner>:repair``; the rows put after the step was recorded are
    looked at as they are put (``repair_put``)."""

    def __init__(
        self, db: Database, clocks: SystemClocks, codecs: Codecs, owner: str, lease_s: float
    ) -> None:
        self.queue_time = open_queue_time(db.write, clocks)
        self._db, self._codecs = db, codecs
        self._owner, self._lease_s = f"{owner}:repair", lease_s
        self.repairing = True  # until a look finds no repair under way (a crash's)
        # the steps this process recorded, in order; read and written under the queue's
        # lock, in the transaction of the look that records a step or of the put
        self._steps: list[Step] = []

    def due(self) -> bool:
        """Whether a claim must look first: a step not seen yet, or a repair under way."""
        return self.repairing or self.queue_time.stepped()

    def look(self) -> float:
        """Record the clocks (``clock.record_moment``); after a step, start repairing
        what was stamped before it; go on with a repair under way for up to
        ``REPAIR_BUDGET_S``, a chunk of rows per transaction, so that a day's backlog
        is repaired over a few looks and never holds the queue for long. The step's
        seconds (0.0 for none)."""
        step, repair = self._db.write(self._record, durable=False)
        if step is not None:
            log.warning(
                "queue %s: the wall clock stepped by %+.1f s; repairing the queued events "
                "of this boot stamped before it",
                self._db.path,
                step.seconds,
            )
        deadline = time.monotonic() + REPAIR_BUDGET_S
        while repair is not None and repair.ranges:  # a chunk at least, then to the budget
            repair = self._db.write(self._repair_chunk, durable=False)
            if time.monotonic() >= deadline:
                break
        if repair is not None and not repair.ranges:
            log.warning(
                "queue %s: %d queued event(s) stamped before the step of %+.1f s repaired",
                self._db.path,
                repair.repaired,
                repair.step.seconds,
            )
        self.repairing = repair is not None and bool(repair.ranges)
        return step.seconds if step else 0.0

    def repair_put(self, cursor: sqlite3.Cursor, rows: int) -> int:
        """In the transaction of a put, after its ``rows`` rows were inserted: repair
        those of their events stamped before a step this process had recorded already.
        Such an event was in flight (built, not yet queued: the writer batches in
        memory) when that step's repair took the rows then in the queue, and would
        otherwise never be repaired. Events put in another process were in flight in
        that process, whose own look sees the step. The events changed."""
        if not self._steps or rows <= 0:
            return 0
        next_id = cursor.execute("SELECT value FROM counters WHERE name = 'next_id'").fetchone()
        found = cursor.execute(
            "SELECT id, count, queued_at, coalesce(newest_at, queued_at), codec, dict_id, "
            "body FROM events WHERE id >= ? ORDER BY id",
            (int(next_id[0]) - rows,),
        ).fetchall()
        return _repair_rows(cursor, self._codecs, found, self._steps, self.queue_time.base)

    def _record(self, cursor: sqlite3.Cursor) -> tuple[Step | None, Repair | None]:
        step = self.queue_time.record(cursor)
        repair = pending_repair(cursor)
        if step is not None:
            # from this transaction on, the rows put are looked at as they are put
            self._steps.append(step)
            if repair is not None:  # a second step before the first's repair ended (rare)
                _repair_ranges(cursor, self._codecs, repair, limit=None)
            repair = _start(cursor, self._codecs, step, self.queue_time.base, self._now())
        if repair is not None:  # the lease renewed, or taken again by a new process
            _save(cursor, repair, self._owner, self._now() + self._lease_s)
        return step, repair

    def _repair_chunk(self, cursor: sqlite3.Cursor) -> Repair | None:
        """The next chunk of rows of the repair under way; the repair as it stands."""
        repair = pending_repair(cursor)
        if repair is not None:
            repair = _repair_ranges(cursor, self._codecs, repair, limit=CHUNK_ROWS)
            _save(cursor, repair, self._owner, self._now() + self._lease_s)
        return repair

    def _now(self) -> float:
        return self.queue_time.now()


def pending_repair(cursor: sqlite3.Cursor) -> Repair | None:
    """The repair under way, if one is."""
    row = cursor.execute("SELECT value FROM meta WHERE key = ?", (REPAIR_KEY,)).fetchone()
    if row is None:
        return None
    kept = orjson.loads(row[0])
    ranges = [(first, last) for first, last in kept["ranges"]]
    return Repair(Step(*kept["step"]), kept["boot_start"], ranges, kept["repaired"])


def _start(
    cursor: sqlite3.Cursor, codecs: Codecs, step: Step, boot_start: float, now: float
) -> Repair | None:
    """A repair of the rows of this boot queued up to the step (ids follow queue time:
    two short lookups from either end find them); None when there are none. Rows a
    sender holds are repaired at once (a batch or two: their sender gives them back
    when it sees the step, ``QueueStore.stepped_since``); the others are left to the
    chunks, under the repairer's lease."""
    first = cursor.execute(
        "SELECT id FROM events WHERE queued_at >= ? ORDER BY id LIMIT 1", (boot_start,)
    ).fetchone()
    last = cursor.execute(
        "SELECT id FROM events WHERE queued_at <= ? ORDER BY id DESC LIMIT 1", (step.at,)
    ).fetchone()
    if first is None or last is None or first[0] > last[0]:
        return None
    span = (first[0], last[0])
    free = leases.gaps(span, leases.live_ranges(cursor, now))
    held = leases.gaps(span, free)
    done = _repair_ranges(cursor, codecs, Repair(step, boot_start, held), limit=None)
    return Repair(step, boot_start, free, done.repaired)


def _save(cursor: sqlite3.Cursor, repair: Repair, owner: str, until: float) -> None:
    """Keep the repair under way and its ranges under ``owner``'s lease; forget it
    once it is done."""
    leases.give_back(cursor, owner)
    if not repair.ranges:
        cursor.execute("DELETE FROM meta WHERE key = ?", (REPAIR_KEY,))
        return
    for first, last in repair.ranges:
        leases.take(cursor, first, last, owner, until)
    kept = {**repair._asdict(), "step": list(repair.step)}
    cursor.execute(
        "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
        (REPAIR_KEY, orjson.dumps(kept).decode()),
    )


def _repair_ranges(
    cursor: sqlite3.Cursor, codecs: Codecs, repair: Repair, limit: int | None
) -> Repair:
    """Repair up to ``limit`` rows (None: all) from the start of the repair's
    ranges; the repair with what is left of them."""
    ranges, repaired = list(repair.ranges), repair.repaired
    while ranges and limit != 0:
        first, last = ranges[0]
        rows = cursor.execute(
            "SELECT id, count, queued_at, coalesce(newest_at, queued_at), codec, dict_id, "
            "body FROM events WHERE id BETWEEN ? AND ? AND queued_at BETWEEN ? AND ? "
            "ORDER BY id LIMIT ?",
            (first, last, repair.boot_start, repair.step.at, -1 if limit is None else limit),
        ).fetchall()
        repaired += _repair_rows(cursor, codecs, rows, [repair.step], repair.boot_start)
        if limit is None or len(rows) < limit:
            ranges.pop(0)
        else:
            ranges[0] = (rows[-1][0] + 1, last)
        limit = None if limit is None else limit - len(rows)
    return repair._replace(ranges=ranges, repaired=repaired)


def _repair_rows(
    cursor: sqlite3.Cursor, codecs: Codecs, rows: list[Any], steps: Sequence[Step], since: float
) -> int:
    """Rewrite the rows (of this boot, which started at queue time ``since``) holding
    events stamped before one of ``steps``; the events changed."""
    changed_events = size_change = 0
    for row_id, count, _first, last, codec, dict_id, body in rows:
        jsons = split_frame(codecs.decode(codec, dict_id, body), count)
        events = [orjson.loads(json) for json in jsons]
        fixed = [repaired(event, (since, last), steps) for event in events]
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
