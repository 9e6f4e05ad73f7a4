"""Claims, the SQL of the sending side: lease the oldest free events, delete what
PhyCloud accepted (moving its rejects to dead letters), and take back the claims of
processes that died. Each runs in the caller's transaction."""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from typing import Any

from phytrace_edge.queue import leases
from phytrace_edge.queue.database import bump_counters
from phytrace_edge.queue.records import Batch, DeadLetterRow
from phytrace_edge.queue.rows import delete_range


def lease_oldest(
    cursor: sqlite3.Cursor, max_events: int, max_bytes: int, token: str, now: float, until: float
) -> list[Any]:
    """Rows (id, last_id, count, queued_at, event_id, codec, dict_id, body) of the oldest
    free
    events: whole rows of at most ``max_events`` events and ``max_bytes`` of JSON
    (always one row), now leased to ``token`` until ``until``."""
    sizes: list[Any] = []
    for low, high in leases.free_ranges(cursor, now):
        sizes = cursor.execute(
            "SELECT id, last_id, count, json_size FROM events WHERE id BETWEEN ? AND ? "
            "ORDER BY id LIMIT ?",
            (low, high, max_events),
        ).fetchall()
        if sizes:
            break
    events, total, keep = 0, 0, 0
    for _, _, count, json_size in sizes:
        if keep and (events + count > max_events or total + json_size > max_bytes):
            break
        events += count
        total += json_size
        keep += 1
    if not keep:
        return []
    first_id, last_id = sizes[0][0], sizes[keep - 1][1]
    leases.take(cursor, first_id, last_id, token, until)
    return cursor.execute(
        "SELECT id, last_id, count, queued_at, event_id, codec, dict_id, body FROM events "
        "WHERE id BETWEEN ? AND ? ORDER BY id",
        (first_id, last_id),
    ).fetchall()


def delete_accepted(
    cursor: sqlite3.Cursor, batch: Batch, dead_letters: Sequence[DeadLetterRow], now: float
) -> None:
    """Delete a batch PhyCloud has, keeping ``dead_letters`` aside first."""
    rejected = 0  # those this ack deletes: after a lease ran out, another may have them
    for dead in dead_letters:
        if not deleted_by(cursor, dead.queue_id, batch):
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
    deleted = delete_range(cursor, batch.first_id, batch.last_id)
    leases.give_back(cursor, batch.first_id, batch.owner)
    bump_counters(
        cursor,
        acked_total=max(0, deleted - rejected),
        dead_letters=rejected,
        **{"drop:rejected": rejected},
    )


def deleted_by(cursor: sqlite3.Cursor, queue_id: int, batch: Batch) -> bool:
    """Whether the event ``queue_id`` is still queued, in a row the ack of ``batch``
    deletes (one wholly within the batch's ids)."""
    row = cursor.execute(
        "SELECT id, last_id FROM events WHERE id <= ? ORDER BY id DESC LIMIT 1", (queue_id,)
    ).fetchone()
    return (
        row is not None
        and queue_id <= row[1]
        and batch.first_id <= row[0] <= row[1] <= batch.last_id
    )


def take_back(cursor: sqlite3.Cursor, dead_owners: list[str]) -> None:
    """Free the leases of owners that died (``ownership.is_alive`` said so)."""
    for token in dead_owners:
        leases.take_back(cursor, token)
