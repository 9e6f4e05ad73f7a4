"""Thinning: a full queue halves its oldest periodic history before it drops anything.

With QUEUE_ON_FULL=thin, when a put does not fit under the caps, the queue walks its
rows from the oldest onward and halves each periodic one it passes: a frame keeps every
other event, and of the single rows it passes (a periodic event alone between two
important ones) every other one, so that after k halvings 1 in 2^k of the periodic
events of that stretch remain, evenly spread. (Single rows were once kept by their id's
parity: with an alarm after every periodic event, every periodic id was odd, and one
walk deleted them all.) What is kept of
neighbouring rows is packed into frames again (decoded and compressed once), so that
the pages it frees are whole pages. Important events are never touched, and neither
are rows a sender holds or rows younger than ``SEAL_AFTER_S`` (the live end).

A walk that reaches the live end starts again from the oldest row, one level deeper,
and halves only rows not already thinner than its level: the oldest history is always
the thinnest, and a robot's recent past keeps the finest resolution. Rows at
1 in 2^MAX_THIN_LEVEL are not thinned further; when nothing is left to thin the caps
drop the oldest periodic events, and important ones only when no periodic ones are
left (``caps.drop_oldest``).

The walk's place is kept in ``meta`` (``thin_walk``: its level and the next row;
``thin_keep_single``: whether the next single row is kept) and each step reads the next
rows by primary key, so thinning costs what it frees, never a scan of the queue.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass, field

from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S, event_id_of, split_frame
from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.storage.database import bump_counters
from phytrace_edge.queue.storage.rows import THINNED_COLUMNS, ThinnedRow

MAX_THIN_LEVEL = 6  # 1 in 64
STEP_ROWS = 256
MAX_WALKS = MAX_THIN_LEVEL + 1  # per call: enough to reach the deepest level once


@dataclass
class _Kept:
    """What is kept of a stretch of neighbouring rows of one thinning level, to be
    written back as one row (halved rows left in place would leave pages half empty,
    and the cap is on pages)."""

    level: int
    free_range: int
    first_id: int
    last_id: int = 0
    events: list[bytes] = field(default_factory=list)
    old_bytes: int = 0
    queued_at: float | None = None  # of the first row that kept an event
    newest_at: float | None = None  # of the last row that kept an event (TTL)


def thin_oldest(
    cursor: sqlite3.Cursor, codecs: Codecs, wanted: int, now: float, frame_events: int
) -> int:
    """Halve periodic rows, oldest first, until about ``wanted`` events are gone (or
    nothing is left to thin), packing what is kept into frames of up to
    ``frame_events``; the number of events removed, counted as ``thinned``."""
    level, next_id, keep_single = _load_walk(cursor)
    free = leases.free_ranges(cursor, now)
    removed, walks, halved_in_walk = 0, 0, False
    kept: _Kept | None = None
    while removed < wanted and walks < MAX_WALKS:
        rows = [
            ThinnedRow._make(row)
            for row in cursor.execute(
                f"SELECT {THINNED_COLUMNS} FROM events WHERE id >= ? ORDER BY id LIMIT ?",
                (next_id, STEP_ROWS),
            )
        ]
        at_live_end = len(rows) < STEP_ROWS
        for row in rows:
            if row.queued_at >= now - SEAL_AFTER_S:
                at_live_end = True
                break
            next_id = row.last_id + 1
            where = _free_range_of(free, row.id, row.last_id)
            if row.important or row.thin_level > level or where is None:
                _write(cursor, codecs, kept)  # a stretch ends here
                kept = None
                continue
            events = split_frame(codecs.decode(row.codec, row.dict_id, row.body), row.events)
            # a frame keeps every other event, always its newest (so its newest_at, the
            # TTL's clock, stays exact); of the single rows, every other one
            if row.events > 1:
                halved = events[(row.events - 1) % 2 :: 2]
            else:
                halved, keep_single = (events if keep_single else []), not keep_single
            if (
                kept is None
                or (kept.level, kept.free_range) != (row.thin_level, where)
                or len(kept.events) + len(halved) > frame_events
            ):
                _write(cursor, codecs, kept)
                kept = _Kept(row.thin_level, where, row.id)
            kept.last_id = row.last_id
            if halved:
                kept.queued_at = row.queued_at if kept.queued_at is None else kept.queued_at
                kept.newest_at = row.newest_at or row.queued_at
            kept.events += halved
            kept.old_bytes += len(row.body)
            removed += row.events - len(halved)
            halved_in_walk = True
            if removed >= wanted:
                break
        _write(cursor, codecs, kept)
        kept = None
        if removed >= wanted or not at_live_end:
            continue
        walks += 1
        if level >= MAX_THIN_LEVEL - 1 and not halved_in_walk:
            break  # nothing left to thin: stay at the live end, the caps drop instead
        level, next_id, halved_in_walk = min(level + 1, MAX_THIN_LEVEL - 1), 0, False
    _save_walk(cursor, level, next_id, keep_single)
    bump_counters(cursor, depth=-removed, **{"drop:thinned": removed})
    return removed


def _free_range_of(free: list[tuple[int, int]], first_id: int, last_id: int) -> int | None:
    """Which free range holds the row wholly (None: a lease holds some of it)."""
    for index, (low, high) in enumerate(free):
        if low <= first_id and last_id <= high:
            return index
    return None


def _write(cursor: sqlite3.Cursor, codecs: Codecs, kept: _Kept | None) -> None:
    """Replace the rows of ``kept`` with one row of what is kept of them (or none)."""
    if kept is None:
        return
    first_id, last_id = kept.first_id, kept.last_id
    cursor.execute("DELETE FROM events WHERE id BETWEEN ? AND ?", (first_id, last_id))
    new_bytes = 0
    if kept.events:
        encoded = codecs.encode(b"\n".join(kept.events))
        new_bytes = len(encoded.body)
        cursor.execute(
            "INSERT INTO events(id, last_id, count, thin_level, queued_at, newest_at, event_id, "
            "codec, dict_id, json_size, body) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                first_id,
                last_id,
                len(kept.events),
                kept.level + 1,
                kept.queued_at,
                kept.newest_at,
                event_id_of(kept.events[0]),
                encoded.codec,
                encoded.dict_id,
                sum(len(event) for event in kept.events),
                encoded.body,
            ),
        )
    bump_counters(cursor, stored_bytes=new_bytes - kept.old_bytes)


def _load_walk(cursor: sqlite3.Cursor) -> tuple[int, int, bool]:
    """The walk's level, its next row and whether its next single row is kept (under a
    key of its own, which a version from before it ignores: a queue it wrote says keep)."""
    rows = dict(cursor.execute("SELECT key, value FROM meta WHERE key LIKE 'thin_%'"))
    keep_single = rows.get("thin_keep_single") != "0"
    if "thin_walk" not in rows:
        return 0, 0, keep_single
    level, next_id = rows["thin_walk"].split(":")
    return int(level), int(next_id), keep_single


def _save_walk(cursor: sqlite3.Cursor, level: int, next_id: int, keep_single: bool) -> None:
    cursor.executemany(
        "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
        [("thin_walk", f"{level}:{next_id}"), ("thin_keep_single", str(int(keep_single)))],
    )
