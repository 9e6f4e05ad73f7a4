"""Claims, the SQL of the sending side: lease events for one of the two lanes (the
backfill, oldest first; the live lane, newest first), delete what PhyCloud accepted
(moving its rejects to dead letters), and take back the claims of processes that
died (``leases.take_back``). Each runs in the caller's transaction."""

from __future__ import annotations

import math
import sqlite3
from collections.abc import Iterable, Sequence
from typing import Any

from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.encoding.frames import decode_rows
from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.records import INCIDENT_CLASS, Batch, DeadLetterRow
from phytrace_edge.queue.storage.database import bump_counters
from phytrace_edge.queue.storage.rows import (
    SIZE_COLUMNS,
    STORED_COLUMNS,
    RowSize,
    StoredRow,
    delete_range,
)

BAND_S = 3600.0  # the backfill's age band: its important events go before its periodic ones

Range = tuple[int, int]
Leased = tuple[list[Range], list[StoredRow]]  # the ranges leased and their rows


def _sized(rows: Iterable[Any]) -> list[RowSize]:
    return [RowSize._make(row) for row in rows]


def lease_oldest(
    cursor: sqlite3.Cursor,
    limits: tuple[int, int],
    token: str,
    now: float,
    until: float,
    important_first: bool = True,
) -> Leased:
    """The backfill lane: lease the oldest free events, whole rows of at most
    ``limits`` = (events, bytes of JSON) (always one row), to ``token`` until
    ``until``; the ranges leased and their rows, oldest first. With ``important_first``,
    incidents' parts go first, whenever they were queued, and then the important events
    of the oldest hour still queued, a lease each (an export takes strictly the oldest)."""
    oldest = next(leases.unleased(cursor, now, SIZE_COLUMNS, limits[0]), None)
    if oldest is None:
        return [], []
    sizes = _sized(oldest.rows)
    if important_first:
        ahead = _unleased_of_class(
            cursor, now, INCIDENT_CLASS, math.inf, limits
        ) or _unleased_of_class(cursor, now, 1, sizes[0].queued_at + BAND_S, limits)
        if ahead:
            return _lease(cursor, [(row.id, row.last_id) for row in ahead], token, until)
    kept = _within(sizes, limits)
    return _lease(cursor, [(sizes[0].id, sizes[kept - 1].last_id)], token, until)


def lease_newest(
    cursor: sqlite3.Cursor,
    limits: tuple[int, int],
    token: str,
    now: float,
    until: float,
    since: float,
) -> Leased:
    """The live lane: lease the newest free events queued at or after ``since``, whole
    rows of at most ``limits`` (always one row); as ``lease_oldest``. The rows are
    one run below the newest, so the lane sends newest first, batch by batch."""
    newest = next(leases.unleased(cursor, now, SIZE_COLUMNS, limits[0], newest_first=True), None)
    # the newest rows no lease covers; if they are older than ``since``, so is all below
    fresh = _takewhile_since(_sized(newest.rows), since) if newest else []
    if not fresh:
        return [], []
    kept = _within(fresh, limits)
    return _lease(cursor, [(fresh[kept - 1].id, fresh[0].last_id)], token, until)


def _takewhile_since(rows: list[RowSize], since: float) -> list[RowSize]:
    taken = []
    for row in rows:
        if row.queued_at < since:
            break
        taken.append(row)
    return taken


def _within(sizes: list[RowSize], limits: tuple[int, int]) -> int:
    """How many of these rows fit in ``limits`` (events, bytes of JSON); at least one."""
    events, total, kept = 0, 0, 0
    for row in sizes:
        count, json_size = row.events, row.json_size
        if kept and (events + count > limits[0] or total + json_size > limits[1]):
            break
        events, total, kept = events + count, total + json_size, kept + 1
    return kept


def _unleased_of_class(
    cursor: sqlite3.Cursor, now: float, row_class: int, before: float, limits: tuple[int, int]
) -> list[RowSize]:
    """Unleased rows of ``row_class`` (1 important, 2 an incident's part) queued before
    ``before``, oldest first, within ``limits`` (found by the class's partial index, not
    a scan: the literal class lets SQLite use it)."""
    if row_class not in (1, INCIDENT_CLASS):
        raise ValueError(f"no index for row class {row_class}")
    rows = _sized(
        cursor.execute(
            f"SELECT {SIZE_COLUMNS} FROM events AS e "
            f"WHERE important = {row_class} AND queued_at < ? AND NOT EXISTS (SELECT 1 "
            "FROM leases WHERE e.id BETWEEN first_id AND last_id AND expires_at > ?) "
            "ORDER BY id LIMIT ?",
            (before, now, limits[0]),
        )
    )
    return rows[: _within(rows, limits)] if rows else []


def _lease(cursor: sqlite3.Cursor, ranges: list[Range], token: str, until: float) -> Leased:
    rows: list[StoredRow] = []
    for first_id, last_id in ranges:
        leases.take(cursor, first_id, last_id, token, until)
        rows += map(
            StoredRow._make,
            cursor.execute(
                f"SELECT {STORED_COLUMNS} FROM events WHERE id BETWEEN ? AND ? ORDER BY id",
                (first_id, last_id),
            ),
        )
    return ranges, rows


def delete_accepted(
    cursor: sqlite3.Cursor,
    batch: Batch,
    dead_letters: Sequence[DeadLetterRow],
    now: float,
    codecs: Codecs,
    counter: str = "acked_total",
) -> None:
    """Delete a batch PhyCloud has, keeping ``dead_letters`` aside first; the deleted
    events count in ``counter`` (``exported_total`` for a hand-carry export)."""
    rejected = 0  # those this ack deletes: after a lease ran out, another may have them
    deleting = _ids_deleted_by(cursor, batch, codecs) if dead_letters else set()
    for dead in dead_letters:
        if dead.event_id not in deleting:
            continue
        cursor.execute(
            "INSERT INTO dead_letters(event_id, queued_at, dead_at, reason, status_code, "
            "response, codec, dict_id, json_size, body) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                dead.event_id,
                dead.queued_at,
                now,
                dead.reason,
                dead.status_code,
                (dead.response or "")[:4096] or None,
                dead.codec,
                dead.dict_id,
                dead.json_size,
                dead.body,
            ),
        )
        rejected += 1
    deleted = sum(delete_range(cursor, first, last) for first, last in batch.ranges)
    leases.give_back(cursor, batch.owner)
    bump_counters(
        cursor,
        **{counter: max(0, deleted - rejected)},
        dead_letters=rejected,
        **{"drop:rejected": rejected},
    )


def _ids_deleted_by(cursor: sqlite3.Cursor, batch: Batch, codecs: Codecs) -> set[str]:
    """The event_ids still queued in rows the ack of ``batch`` deletes (those wholly
    within its ranges). Read by event_id, not queue id: thinning may have repacked a
    frame since the claim, and then its events' queue ids moved."""
    ids: set[str] = set()
    for first, last in batch.ranges:
        rows = cursor.execute(
            f"SELECT {STORED_COLUMNS} FROM events WHERE id BETWEEN ? AND ? AND last_id <= ?",
            (first, last, last),
        )
        stored = [StoredRow._make(row) for row in rows]
        ids.update(event.event_id for event in decode_rows(codecs, stored))
    return ids
