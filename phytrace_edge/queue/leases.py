"""Leases: a sender's claim on a range of event ids, as a row in the database, so two
processes (the service and an operator's ``drain``) never send the same events at the
same time, and a crashed sender's claim expires and its events come back."""

from __future__ import annotations

import sqlite3

from phytrace_edge.queue.rows import MAX_ID


def free_ranges(cursor: sqlite3.Cursor, now: float) -> list[tuple[int, int]]:
    """Id ranges no live lease covers, oldest first (expired leases are removed)."""
    cursor.execute("DELETE FROM leases WHERE expires_at <= ?", (now,))
    ranges, low = [], 0
    for first, last in cursor.execute("SELECT first_id, last_id FROM leases ORDER BY first_id"):
        if first > low:
            ranges.append((low, first - 1))
        low = max(low, last + 1)
    ranges.append((low, MAX_ID))
    return ranges


def take(cursor: sqlite3.Cursor, first_id: int, last_id: int, owner: str, until: float) -> None:
    cursor.execute(
        "INSERT INTO leases(first_id, last_id, owner, expires_at) VALUES (?, ?, ?, ?)",
        (first_id, last_id, owner, until),
    )


def give_back(cursor: sqlite3.Cursor, owner: str) -> None:
    """End a claim (every claim has its own token: this frees no other)."""
    cursor.execute("DELETE FROM leases WHERE owner = ?", (owner,))


def extend(cursor: sqlite3.Cursor, owner: str, now: float, until: float) -> bool:
    """Extend a claim's leases that have not expired; False if they had (or are gone)."""
    cursor.execute(
        "UPDATE leases SET expires_at = ? WHERE owner = ? AND expires_at > ?",
        (until, owner, now),
    )
    return cursor.rowcount > 0


def take_back(cursor: sqlite3.Cursor, dead_owners: list[str]) -> int:
    """Remove every lease of owners that died (``ownership`` said so; a claim's owner is
    ``<owner token>:<claim>``): their events are claimable again at once. The count."""
    taken = 0
    for token in dead_owners:
        cursor.execute(
            "DELETE FROM leases WHERE substr(owner, 1, ?) = ?", (len(token) + 1, token + ":")
        )
        taken += cursor.rowcount
    return taken
