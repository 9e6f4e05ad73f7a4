"""Leases: a sender's claim on a range of event ids, as a row in the database, so two
processes (the service and an operator's ``drain``) never send the same events at the
same time, and a crashed sender's claim expires and its events come back."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from typing import Any, NamedTuple

from phytrace_edge.queue.storage.rows import MAX_ID


def free_ranges(cursor: sqlite3.Cursor, now: float) -> list[tuple[int, int]]:
    """Id ranges no live lease covers, oldest first (expired leases are removed)."""
    return gaps((0, MAX_ID), live_ranges(cursor, now))


def live_ranges(cursor: sqlite3.Cursor, now: float) -> list[tuple[int, int]]:
    """The id ranges of the live leases by first id (expired leases are removed)."""
    cursor.execute("DELETE FROM leases WHERE expires_at <= ?", (now,))
    return cursor.execute("SELECT first_id, last_id FROM leases ORDER BY first_id").fetchall()


def gaps(span: tuple[int, int], ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The parts of ``span`` (first, last id) that no range of ``ranges`` covers; the
    ranges sorted by first id, overlapping or not. Pure."""
    found, low = [], span[0]
    for first, last in ranges:
        if first > span[1]:
            break
        if first > low:
            found.append((low, first - 1))
        low = max(low, last + 1)
    if low <= span[1]:
        found.append((low, span[1]))
    return found


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


class Chunk(NamedTuple):
    """Rows no live lease covers, read in one query: all lie within ``low..high``,
    a stretch free of leases (so deleting ``low..`` a row's last id touches no claim)."""

    low: int
    high: int
    rows: list[Any]  # the columns asked for (``id`` first)


def unleased(
    cursor: sqlite3.Cursor,
    now: float,
    columns: str,
    chunk_rows: int,
    where: str = "",
    newest_first: bool = False,
    from_id: int = 0,
) -> Iterator[Chunk]:
    """Walk the rows no live lease covers (from ``from_id`` on), oldest first or newest
    first, up to ``chunk_rows`` a query: ``SELECT <columns> FROM events``, ``columns``
    starting with ``id``, ``where`` adding a condition. The caller may delete what it
    was given before asking for more: the walk goes on after each chunk's last row."""
    ranges = [(max(low, from_id), high) for low, high in free_ranges(cursor, now)]
    order = "DESC" if newest_first else "ASC"
    sql = (
        f"SELECT {columns} FROM events WHERE id BETWEEN ? AND ? {where} ORDER BY id {order} LIMIT ?"
    )
    for low, high in reversed(ranges) if newest_first else ranges:
        while low <= high:
            rows = cursor.execute(sql, (low, high, chunk_rows)).fetchall()
            if rows:
                yield Chunk(low, high, rows)
            if len(rows) < chunk_rows:
                break
            if newest_first:
                high = rows[-1][0] - 1
            else:
                low = rows[-1][0] + 1
