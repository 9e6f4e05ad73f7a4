"""Claims, the SQL of the sending side: lease the oldest free events, delete what
PhyCloud accepted (moving its rejects to dead letters), and take back the claims of
processes that died. Each runs in the caller's transaction."""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from typing import Any

from phytrace_edge.queue import leases
from phytrace_edge.queue.database import bump_counters
from phytrace_edge.queue.records import Batch, DeadLetter
from phytrace_edge.queue.rows import delete_range


def lease_oldest(
    cursor: sqlite3.Cursor, max_events: int, max_bytes: int, token: str, now: float, until: float
) -> list[Any]:
    """Rows (id, event_id, codec, dict_id, json_size, body) of the oldest unleased
    events, at most ``max_events`` and ``max_bytes`` of JSON (always one), now leased
    to ``token`` until ``until``."""
    rows: list[Any] = []
    for low, high in leases.free_ranges(cursor, now):
        rows = cursor.execute(
            "SELECT id, event_id, codec, dict_id, json_size, body FROM events "
            "WHERE id BETWEEN ? AND ? ORDER BY id LIMIT ?",
            (low, high, max_events),
        ).fetchall()
        if rows:
            break
    total, keep = 0, 0
    for _, _, _, _, json_size, _ in rows:
        if keep and total + json_size > max_bytes:
            break
        total += json_size
        keep += 1
    if keep:
        leases.take(cursor, rows[0][0], rows[keep - 1][0], token, until)
    return rows[:keep]


def delete_accepted(
    cursor: sqlite3.Cursor, batch: Batch, dead_letters: Sequence[DeadLetter], now: float
) -> None:
    """Delete a batch PhyCloud has, moving ``dead_letters`` aside first."""
    rejected = 0  # those still queued: after a lease ran out, another may have them
    for dead in dead_letters:
        rejected += cursor.execute(
            "INSERT INTO dead_letters(event_id, queued_at, dead_at, reason, status_code, "
            "response, codec, dict_id, json_size, body) "
            "SELECT event_id, queued_at, ?, ?, ?, ?, codec, dict_id, json_size, body "
            "FROM events WHERE id = ?",
            (
                now,
                dead.reason,
                dead.status_code,
                (dead.response or "")[:4096] or None,
                dead.queue_id,
            ),
        ).rowcount
    deleted = delete_range(cursor, batch.first_id, batch.last_id)
    leases.give_back(cursor, batch.first_id, batch.owner)
    bump_counters(
        cursor,
        acked_total=max(0, deleted - rejected),
        dead_letters=rejected,
        **{"drop:rejected": rejected},
    )


def take_back(cursor: sqlite3.Cursor, dead_owners: list[str]) -> None:
    """Free the leases of owners that died (``ownership.is_alive`` said so)."""
    for token in dead_owners:
        leases.take_back(cursor, token)
